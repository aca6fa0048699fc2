"""The bench box's daemon: scans run by themselves, survive faults and power loss.

    service.py     BenchService, the public facade (web UI, CLI, tests)
    rpc.py         the facade over a Unix socket; BenchClient for the web service
    runner.py      one scan: home, levels, settle, light, capture, write, process
    levels.py      which level next: fixed or adaptive step, a pure function of the frames so far
    store.py       SQLite (WAL, synchronous=FULL): jobs, settings, calibration history, events
    recovery.py    at start: mark interrupted jobs, make scan folders agree with scan.json; audit()
    settings.py    defaults and validation naming the bad key
    processing.py  process_scan in a child process (memory, cancel), or in-process
    notify.py      sd_notify (READY, WATCHDOG, STATUS) without a dependency
    notices.py     what the front panel tells the operator (USB copy outcomes), as data
    firstrun.py    the web's first-run password handed to the display through a 0600 file
    livemap.py     the height map so far, for the dashboard during a scan
    calibration.py guided plane calibration, step by step from the web UI
    importing.py   an uploaded scan folder checked and copied into a new job
    main.py        the process: service + socket + watchdog loop + clean SIGTERM

Devices come from a factory: appliance.hw.devices.HardwareBench (the real
bench), appliance.sim.fakes.FakeBench / SimulatedBenchFactory (fakes, and
the firmware under simavr with the virtual camera).
"""
