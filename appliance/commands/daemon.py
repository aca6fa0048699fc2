"""inkslice daemon: the bench box's scan service (systemd runs it as inkslice-daemon)."""

import json

from .. import datadir
from ..errors import SettingError
from ._flags import add_daemon_paths

NAME = "daemon"
ORDER = 60
HELP = "run the scan daemon (state machine, job store, recovery) on the real or a simulated bench"


def add_arguments(p):
    add_daemon_paths(p)
    p.add_argument(
        "--wiring",
        default="/etc/inkslice/bench.json",
        help="the real bench's device paths and GPIO lines (JSON; see appliance/hw/devices.py)",
    )
    p.add_argument(
        "--sim",
        choices=("fake", "simavr"),
        default=None,
        help="no hardware: 'fake' = in-memory stage and camera, 'simavr' = the firmware under "
        "simavr with the virtual camera",
    )
    p.add_argument("--surface", default="sphere", help="the part on the simulated bench (default sphere)")
    p.add_argument("--frame", default="320x240", help="simulated frame size WxH (default 320x240)")
    p.add_argument(
        "--effects",
        default=None,
        help="--sim simavr: the virtual camera's effects preset (clean, optics, realistic, physics, "
        "harsh; default clean); physics adds the ink's displacement and meniscus",
    )
    p.add_argument(
        "--level-zero",
        type=float,
        default=None,
        metavar="MM",
        help="simulated benches: the true stage position where the base top meets the ink (default: "
        "whatever the daemon's setting level_at_home_mm says; commissioning measures it)",
    )
    p.add_argument(
        "--replay",
        default=None,
        help="--sim fake: serve frames rendered beforehand from this folder (one PNG per level, "
        "see sim/fakes.py ReplayCamera) instead of rendering in the daemon",
    )
    p.add_argument("--faults", default=None, help="fault switches for --sim fake, as JSON (see sim/fakes.py)")
    p.add_argument(
        "--processor",
        choices=("child", "inprocess"),
        default="child",
        help="process scans in a child process (default; protects the daemon's memory) or in-process",
    )
    p.add_argument("--log-level", default="INFO")


def frame_size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SettingError("--frame", f"want WIDTHxHEIGHT, got {text!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise SettingError("--frame", f"{w}x{h} is not a sensible frame size")
    return w, h


def make_factory(args):
    if args.sim is None:
        from ..hw.devices import HardwareBench, load_wiring

        return HardwareBench(load_wiring(args.wiring))
    from ..sim.fakes import FakeBench, SimulatedBenchFactory, small_rig

    rig = small_rig(*frame_size(args.frame))
    if args.sim == "fake":
        try:
            faults = json.loads(args.faults) if args.faults else {}
        except json.JSONDecodeError as e:
            raise SettingError("--faults", f"not valid JSON ({e})") from None
        return FakeBench(args.surface, rig, faults, replay=args.replay, level_at_home_mm=args.level_zero)
    if args.effects is not None:
        from ..sim.effects import effects_preset

        effects_preset(args.effects)  # SettingError naming the presets
    return SimulatedBenchFactory(args.surface, rig, effects=args.effects, level_at_home_mm=args.level_zero)


def run(args):
    from ..daemon.main import run as run_daemon
    from ..daemon.main import setup_logging
    from ..daemon.processing import child_process, in_process

    setup_logging(args.log_level)
    from ..logfiles import log_to_file

    log_to_file(datadir.data_dir(args.data), "daemon")  # the system page shows the last lines
    factory = make_factory(args)
    processor = child_process if args.processor == "child" else in_process
    if args.sim is not None:
        processor = factory.processor(processor)  # the simulated part's truth: statistics in the report
    return run_daemon(factory, args.data, args.socket, processor)
