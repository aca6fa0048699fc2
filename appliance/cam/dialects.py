"""Rule checkers for controllers we cannot run here: GRBL and Fanuc.

LinuxCNC's own interpreter (`rs274 -g`) checks the LinuxCNC and Mach3/4
output in the tests; GRBL and Fanuc controllers are not available, so these
checkers encode their documented rules (and the traps listed in
docs/method.md). Each returns a list of problems, "line N: what", empty when clean.
"""

from __future__ import annotations

import re

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")

GRBL_G = {
    0,
    1,
    2,
    3,
    4,
    10,
    17,
    18,
    19,
    20,
    21,
    28,
    28.1,
    30,
    30.1,
    38.2,
    38.3,
    38.4,
    38.5,
    40,
    43.1,
    49,
    53,
    54,
    55,
    56,
    57,
    58,
    59,
    61,
    80,
    90,
    91,
    91.1,
    92,
    92.1,
    93,
    94,
}
GRBL_M = {0, 1, 2, 3, 4, 5, 7, 8, 9, 30}
GRBL_LETTERS = set("GMFSTXYZIJKLNPR")


def _strip(line):
    return re.sub(r"\([^()]*\)", "", line).split(";")[0].strip()


def check_grbl(text: str) -> list:
    """GRBL 1.1: <= 80 characters a line, >= 3 decimals on coordinates in mm, known words only,
    no N numbers or % (senders), no G64 or M6."""
    problems = []
    for no, raw in enumerate(text.splitlines(), start=1):
        if len(raw) > 80:
            problems.append(f"line {no}: {len(raw)} characters (GRBL takes 80)")
        if "(" in raw and re.search(r"\([^)]*\(", raw):
            problems.append(f"line {no}: nested comment")
        line = _strip(raw)
        if not line:
            continue
        if line.startswith("%"):
            problems.append(f"line {no}: '%' is not GRBL")
            continue
        for letter, val in _WORD.findall(line):
            L = letter.upper()
            if L not in GRBL_LETTERS:
                problems.append(f"line {no}: word {letter}{val} is not GRBL")
            elif L == "N":
                problems.append(f"line {no}: N number (some GRBL senders reject them)")
            elif L == "G" and float(val) not in GRBL_G:
                problems.append(f"line {no}: G{val} is not supported by GRBL")
            elif L == "M" and float(val) not in GRBL_M:
                problems.append(f"line {no}: M{val} is not supported by GRBL")
            elif L in "XYZ":
                dec = len(val.split(".")[1]) if "." in val else 0
                if dec < 3:
                    problems.append(f"line {no}: {letter}{val} has fewer than 3 decimals")
        rest = _WORD.sub("", line).strip()
        if rest:
            problems.append(f"line {no}: cannot read {rest!r}")
    return problems


def check_fanuc(text: str) -> list:
    """Fanuc-style: % first and last, O program number, a decimal point on every coordinate
    and feed (X10 is 10 microns there), comments in capitals."""
    problems = []
    lines = text.splitlines()
    if not lines or lines[0].strip() != "%":
        problems.append("line 1: a Fanuc program starts with %")
    if not lines or lines[-1].strip() != "%":
        problems.append(f"line {len(lines)}: a Fanuc program ends with %")
    if len(lines) < 2 or not re.fullmatch(r"O\d{4}", lines[1].strip()):
        problems.append("line 2: program number O#### expected")
    for no, raw in enumerate(lines, start=1):
        for c in re.findall(r"\(([^()]*)\)", raw):
            if c != c.upper():
                problems.append(f"line {no}: comment not in capitals")
        line = _strip(raw)
        if not line or line == "%" or re.fullmatch(r"O\d{4}", line):
            continue
        for letter, val in _WORD.findall(line):
            if letter.upper() in "XYZF" and "." not in val:
                problems.append(f"line {no}: {letter}{val} has no decimal point")
    return problems
