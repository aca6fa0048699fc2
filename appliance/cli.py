"""The one `inkslice` command.

Sub-commands live in appliance/commands/, one module each, found at start-up:
a module defines NAME, HELP, add_arguments(parser) and run(args) -> exit code.
Each is a thin layer over library functions that tests call directly.

Any InkSliceError becomes one line on stderr, `inkslice: error: WHERE: PROBLEM`,
and exit code 2; so does a file system that refuses our writes (full, over quota,
read-only): every file is written atomically, so what was there before is intact.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import pkgutil
import sys

from . import __version__, commands, progress
from .errors import InkSliceError
from .forks import workers_allowed

WRITE_REFUSED = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS)


def _command_modules():
    mods = []
    for info in pkgutil.iter_modules(commands.__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{commands.__name__}.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    return sorted(mods, key=lambda m: getattr(m, "ORDER", 50))


def build_parser():
    parser = argparse.ArgumentParser(
        prog="inkslice", description="InkSlice: liquid-level 3D scanning to G-code."
    )
    parser.add_argument("--version", action="version", version=f"inkslice {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run, _progress=getattr(mod, "PROGRESS", False))
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        # a long command (PROGRESS = True) shows its stages: progress.py
        with progress.shown() if args._progress else contextlib.nullcontext(), workers_allowed():
            return int(args._run(args) or 0)
    except InkSliceError as e:
        print(f"inkslice: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        if e.errno not in WRITE_REFUSED:
            raise
        print(
            f"inkslice: error: {e.filename or 'writing the outputs'}: {e.strerror} "
            "(the files already there are unchanged)",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print("inkslice: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
