"""inkslice serve: the web UI on the LAN (waitress)."""
from __future__ import annotations

from pathlib import Path

NAME = "serve"
ORDER = 60
HELP = "serve the web UI (phone/desktop) with waitress"


def add_arguments(p):
    p.add_argument("--host", default="0.0.0.0", help="address to listen on (default: all, for the LAN)")
    p.add_argument("--port", type=int, default=8080)
    p.add_argument("--data", default="var", help="data folder (jobs, settings, the web's password hash)")
    p.add_argument("--https", action="store_true",
                   help="mark the session cookie Secure (use when a TLS proxy fronts the box)")
    p.add_argument("--fake", action="store_true",
                   help="run against the simulated FakeBenchService instead of the daemon (UI work, demos)")
    p.add_argument("--no-usb", action="store_true", help="hide USB stick export")


def _service(args):
    if args.fake:
        from ..web.fake import FakeBenchService
        return FakeBenchService(Path(args.data) / "fake", level_s=0.5)
    from ..daemon.service import BenchService     # the daemon team's facade
    return BenchService.from_data_dir(args.data) if hasattr(BenchService, "from_data_dir") else BenchService(args.data)


def run(args):
    from ..web.demo import serve
    service = _service(args)
    config = {"https": args.https}
    if args.no_usb:
        config["usb"] = None
    try:
        serve(service, args.data, host=args.host, port=args.port, config=config)
    finally:
        service.close()
    return 0
