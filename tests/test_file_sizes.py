"""No source file of the product holds more than one idea's worth of lines (issue 22).

A file over MAX_LINES is a file a newcomer cannot hold in mind, and in this package it
has always meant several ideas in one module (the daemon's facade, job threads, import,
USB, preview and front panel were once one 591-line file). Split it by idea, one module
per idea named for what it holds. The simulators (appliance/sim/, and the firmware's simavr
bench in appliance/firmware/stepper/sim/) are left out: they are test equipment, not the product.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "appliance"
MAX_LINES = 450
SOURCES = ("*.py", "*.js", "*.html", "*.css", "*.c", "*.h")


def product_sources(root: Path = PACKAGE) -> list[Path]:
    files = {f for pattern in SOURCES for f in root.rglob(pattern)}
    return sorted(f for f in files if "sim" not in f.relative_to(root).parts[:-1])


def too_long(files) -> list[str]:
    found = []
    for f in files:
        n = len(f.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES:
            found.append(f"{f}: {n} lines")
    return found


def test_no_product_source_file_exceeds_the_limit():
    assert too_long(product_sources()) == []


def test_the_check_sees_the_product_and_leaves_out_only_the_simulator():
    files = [f.relative_to(PACKAGE).as_posix() for f in product_sources()]
    assert {"daemon/service.py", "web/static/app.js", "firmware/stepper/src/main.c"} <= set(files)
    assert not any(f.startswith(("sim/", "firmware/stepper/sim/")) for f in files)


def test_a_file_over_the_limit_is_named_with_its_length(tmp_path):
    (tmp_path / "short.py").write_text("x = 1\n" * MAX_LINES)
    (tmp_path / "long.py").write_text("x = 1\n" * (MAX_LINES + 1))
    assert too_long(product_sources(tmp_path)) == [f"{tmp_path / 'long.py'}: {MAX_LINES + 1} lines"]
