"""inkslice serve: the web UI on the LAN (waitress).

By default it talks to the running daemon over its Unix socket
(rpc.BenchClient), so the web server needs no device access and can run as
its own, less privileged service. --fake runs the daemon's BenchService in this
process instead, on the in-memory bench (sim.fakes.FakeBench: a cone under a virtual
camera), its data in DATA/fake-bench: UI work and demos without a daemon or devices.
"""

from __future__ import annotations

from pathlib import Path

from .. import datadir
from ._flags import add_daemon_paths, add_web_address

NAME = "serve"
ORDER = 60
HELP = "serve the web UI (phone/desktop) with waitress"


def add_arguments(p):
    add_web_address(p, "0.0.0.0", "address to listen on (default: all, for the LAN)")
    add_daemon_paths(p, datadir.HELP + "; the web keeps its password hash in DATA/web/")
    p.add_argument(
        "--https",
        action="store_true",
        help="mark the session cookie Secure (use when a TLS proxy fronts the box)",
    )
    p.add_argument(
        "--fake",
        action="store_true",
        help="run the daemon's BenchService here on the in-memory bench instead of talking to "
        "the daemon (UI work, demos)",
    )
    p.add_argument("--no-usb", action="store_true", help="hide USB stick export")
    p.add_argument(
        "--new-password",
        action="store_true",
        help="replace the admin password by a fresh generated one and print it (demo; "
        "logs every session out)",
    )


def run(args):
    from ..web.server import serve

    data = datadir.data_dir(args.data)
    import logging

    from ..logfiles import log_to_file

    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    log_to_file(data, "web")  # the system page shows the last lines
    if args.fake:
        from ..daemon.service import BenchService
        from ..sim.fakes import FakeBench

        service = BenchService(Path(data) / "fake-bench", FakeBench("cone"))
    else:
        from ..daemon.rpc import BenchClient
        from ..errors import DeviceError

        sock = Path(args.socket or Path(data) / "daemon.sock")
        if not sock.exists():
            raise DeviceError(sock, "no daemon socket here; start `inkslice daemon` first (or use --fake)")
        service = BenchClient(sock)
    config = {"https": args.https, "reset_password": args.new_password}
    if args.fake:
        config["bench_data_dir"] = str(Path(data) / "fake-bench")  # its display shows the password
    if args.no_usb:
        config["usb"] = False
    try:
        serve(service, data, host=args.host, port=args.port, config=config)
    finally:
        service.close()
    return 0
