"""inkslice firmware: build the stage controller's firmware or flash it.

The sources ship inside the package (appliance/firmware), so this works from an
installed copy: the build goes to a cache folder, never into site-packages.
Flashing goes through the board's bootloader with avrdude; stop the daemon
first, it holds the serial port.
"""

from __future__ import annotations

NAME = "firmware"
ORDER = 70
HELP = "build the stage controller's firmware, or flash it over USB serial (avrdude)"


def add_arguments(p):
    p.add_argument(
        "action", choices=("build", "flash"), help="build: the HEX only; flash: build, then write it"
    )
    p.add_argument("--port", default="/dev/inkslice-stage", help="the controller's serial port (flash)")
    p.add_argument(
        "--programmer", default="arduino", help="avrdude programmer (default arduino: the bootloader)"
    )
    p.add_argument("--baud", type=int, default=115200, help="bootloader speed (old Nano bootloaders: 57600)")
    p.add_argument("--dry-run", action="store_true", help="flash: build and print the avrdude command only")


def run(args):
    from .. import firmware

    if args.action == "build":
        out = firmware.build(("firmware",))
        print(out / firmware.HEX)
        return 0
    cmd = firmware.flash(args.port, args.programmer, args.baud, dry_run=args.dry_run)
    print(" ".join(cmd) if args.dry_run else f"flashed {args.port}")
    return 0
