"""inkslice bench NAME: run one of the checkout's benchmarks (benches/NAME.py)."""

import runpy
import sys
from pathlib import Path

from ..errors import SettingError

NAME = "bench"
ORDER = 80
HELP = "run a benchmark from benches/ and print its figures"

BENCHES = Path(__file__).resolve().parents[2] / "benches"


def available():
    return (
        sorted(p.stem for p in BENCHES.glob("*.py") if not p.stem.startswith("_")) if BENCHES.is_dir() else []
    )


def add_arguments(p):
    p.add_argument("name", help="benchmark name (file in benches/ without .py), or 'list'")
    p.add_argument("rest", nargs="*", help="arguments passed to the benchmark (e.g. --quick)")


def run(args):
    names = available()
    if args.name == "list":
        print("\n".join(names) if names else "no benches/ folder beside the package")
        return 0
    if args.name not in names:
        raise SettingError(
            "bench", f"no benchmark named {args.name!r}; available: {', '.join(names) or 'none'}"
        )
    sys.argv = [str(BENCHES / f"{args.name}.py"), *args.rest]
    runpy.run_path(sys.argv[0], run_name="__main__")
    return 0
