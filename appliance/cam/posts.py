"""Post-processors: one Program, several controllers' dialects.

Each dialect's traps (docs/method.md, checked by tests with LinuxCNC's own
interpreter `rs274 -g` and by our GRBL/Fanuc rule checkers in dialects.py):

linuxcnc  No program number (LinuxCNC rejects `O0000`: O-words are
          subroutines there); every G1 needs an F before it (we put F on the
          first feed move and on every change); G64 P<chord> lets the
          trajectory planner blend within the chord tolerance; 4 decimals.
grbl      >= 3 decimals in mm, lines <= 80 characters (comments are wrapped
          short), no G64, no M6, no N numbers, no `%`; only the words GRBL
          knows (G0 G1 G17 G21 G90 G94, M3 M5 M30, F S X Y Z).
mach3     Mach3/4: N numbers (some senders choke on them, so they step by
          10 and are the only difference that matters), G64 without P
          (constant velocity), 4 decimals.
fanuc     `%` first and last, a program number O0001, N numbers, every
          coordinate with a decimal point (on a Fanuc `X10` is 10 *microns*),
          3 decimals, G54 work offset named, comments in capitals.

The dissertation's own format is not a dialect of a Program (it has no
cutter compensation at all): see seed.py; the toolpath command
offers it as `--dialect dissertation` for comparison.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import SettingError
from .program import FEED, RAPID, Program


@dataclass(frozen=True)
class Dialect:
    name: str
    decimals: int
    numbers: bool  # N words
    percent: bool  # % first and last line
    program_number: bool  # O0001
    start: tuple  # modal set-up lines
    upper_comments: bool
    comment_width: int  # wrap comments to this many characters


DIALECTS = {
    "linuxcnc": Dialect(
        "linuxcnc", 4, False, False, False, ("G21 G90 G17 G94 G40 G49 G80", "G64 P{chord}"), False, 200
    ),
    "grbl": Dialect("grbl", 3, False, False, False, ("G21 G90 G17 G94",), False, 70),
    "mach3": Dialect("mach3", 4, True, False, False, ("G21 G90 G17 G94 G40 G49 G80", "G64"), False, 200),
    "fanuc": Dialect("fanuc", 3, True, True, True, ("G21 G90 G17 G94 G40 G49 G80", "G54"), True, 60),
}
DEFAULT_DIALECT = "linuxcnc"
COARSEST = min(d.decimals for d in DIALECTS.values())
DIALECT_NAMES = tuple(DIALECTS) + ("dissertation",)


def get_dialect(name) -> Dialect:
    try:
        return DIALECTS[name]
    except KeyError:
        raise SettingError(
            "dialect", f"unknown dialect {name!r}; known: {', '.join(DIALECT_NAMES)}"
        ) from None


def gcode_number(v, dec):
    """A word's value with `dec` decimals, never "-0.000"."""
    s = f"{v:.{dec}f}"
    if s.startswith("-") and float(s) == 0:
        s = s[1:]
    return s


def _wrap(text, width):
    words, lines, cur = text.split(), [], ""
    for w in words:
        if cur and len(cur) + 1 + len(w) > width:
            lines.append(cur)
            cur = w
        else:
            cur = f"{cur} {w}" if cur else w
    if cur:
        lines.append(cur)
    return lines


def header_lines(prog: Program, runtime_s: float, extra=()):
    c = prog.cutter
    return [
        prog.title,
        f"inkslice cutter: {c.describe()}",
        f"Z frame: program Z = height above the base top + {prog.z_offset:.3f} mm work offset",
        f"inkslice z_offset: {prog.z_offset:.4f}",
        f"safe Z {prog.safe_z:.3f}, spindle {prog.rpm:.0f} rpm",
        f"estimated run time {runtime_s / 60:.1f} min",
    ] + list(extra)


def render(prog: Program, dialect: str, runtime_s: float, chord: float = 0.002, extra_notes=()) -> str:
    d = get_dialect(dialect)
    out = []
    for h in header_lines(prog, runtime_s, extra_notes):
        out.extend(comment_lines(d, h))
    for s in d.start:
        out.append(s.format(chord=gcode_number(chord, d.decimals)))
    out.append(f"M3 S{prog.rpm:.0f}")
    out.extend(motion_lines(prog, d))
    out.append("M5")
    out.append("M30")
    return finish_lines(d, out)


def comment_lines(d: Dialect, text: str) -> list:
    """One comment in the dialect's form: brackets for inner parentheses, wrapped, capitals for Fanuc."""
    t = text.replace("(", "[").replace(")", "]")
    if d.upper_comments:
        t = t.upper()
    return [f"({piece})" for piece in _wrap(t, d.comment_width)]


def _numbers(values, dec) -> list:
    """gcode_number of every value, in one pass (a finishing program has ~10^5 moves, and
    the call per word was a third of posting one)."""
    spec = f".{dec}f"
    out = [format(v, spec) for v in values.tolist()]
    # "-0.000" (a negative that rounds to zero) loses its sign
    return [t[1:] if t[0] == "-" and not t.strip("-0.") else t for t in out]


def motion_lines(prog: Program, d: Dialect) -> list:
    """The program's moves, modal: a word is written only when it changes. The first
    move (straight up to the safe height) writes Z alone, whatever came before it."""
    out = []
    last = [None, None, None]
    last_g, last_f = None, None
    at = None  # where the last move went, at the coarsest dialect's resolution
    coarse = list(zip(*(_numbers(prog.xyz[:, ax], COARSEST) for ax in range(3))))
    words_of = [_numbers(prog.xyz[:, ax], d.decimals) for ax in range(3)]
    feeds = _numbers(prog.feed, 0 if d.name != "fanuc" else 1)
    kinds = prog.kind.tolist()
    for k in range(len(kinds)):
        # a move to within a rounding of where we are is left out in every dialect alike
        # (one written with 3 decimals and kept with 4 made the dialects' moves differ)
        here = coarse[k]
        if here == at:
            continue
        at = here if k > 0 else None  # the opening retract writes Z alone: X and Y are not there yet
        g = "G0" if kinds[k] == RAPID else "G1"
        words = [g] if g != last_g else []
        for ax, name in enumerate("XYZ"):
            if k == 0 and ax < 2:
                continue  # the opening retract moves Z only
            s = words_of[ax][k]
            if s != last[ax]:
                words.append(name + s)
                last[ax] = s
        if kinds[k] == FEED:
            f = feeds[k]
            if f != last_f:
                words.append("F" + f)
                last_f = f
        if len(words) == (1 if g != last_g else 0) and words[:1] == [g]:
            words = []  # a move to where we already are
        if not words:
            continue
        last_g = g if words[0] in ("G0", "G1") else last_g
        out.append(" ".join(words))
    return out


def finish_lines(d: Dialect, out: list) -> str:
    """N numbers, the program number and the percent signs the dialect wants; the text."""
    if d.numbers:
        out = [line if line.startswith("(") else f"N{10 * (i + 1)} {line}" for i, line in enumerate(out)]
    if d.program_number:
        out.insert(0, "O0001")
    if d.percent:
        out = ["%"] + out + ["%"]
    return "\n".join(out) + "\n"
