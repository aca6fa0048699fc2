"""Reading G-code back: the subset our posts (and the dissertation) write.

We parse it ourselves rather than with pygcode: what verification needs is
small (G0/G1 with X Y Z F, G90/G91, G20/G21, comments, N and O words, `%`),
and every word we do not understand must be an *error naming the line*, not
silently skipped: a verifier that ignores a word it does not know can pass a
program that mills something else. pygcode parses far more than we emit and
would add a dependency for no gain. Arcs (G2/G3) are refused with that
reason; we never write them.

Returns the moves in order, in mm and absolute coordinates, plus the header
comments (our programs state the cutter and the Z frame there). A program of
several tools changes them with `Tn M6` and applies the tool-length offset
with `G43 Hn` (program Z is then the tool tip, as it is for one tool): each
move carries the number of the tool in the spindle (0 before the first change).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import InkSliceError

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_IGNORED_G = {17, 40, 49, 54, 55, 56, 57, 58, 59, 61, 64, 80, 94}
_IGNORED_M = {0, 1, 3, 4, 5, 6, 7, 8, 9}


@dataclass
class Parsed:
    kind: np.ndarray  # 0 rapid, 1 feed
    xyz: np.ndarray  # (n, 3) end points; NaN for an axis never set yet
    feed: np.ndarray  # mm/min at each move (NaN for rapids)
    line: np.ndarray  # source line number of each move
    comments: list = field(default_factory=list)
    tool: np.ndarray | None = None  # tool number in the spindle at each move (0: never changed)

    def meta(self, key):
        """Value of a header comment `key: value` (case-insensitive), or None."""
        k = key.lower() + ":"
        for c in self.comments:
            if c.lower().startswith(k):
                return c[len(k) :].strip()
        return None


def parse_gcode(text: str, where="G-code") -> Parsed:
    mode, absolute, scale, feed = None, True, 1.0, None
    pos = [np.nan, np.nan, np.nan]
    kinds, pts, feeds, lines, comments, tools = [], [], [], [], [], []
    selected, spindle = None, 0
    ended = False
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line == "%":
            continue
        # comments: (...) anywhere, ; to the end
        for c in re.findall(r"\(([^()]*)\)", line):
            comments.append(c.strip())
        line = re.sub(r"\([^()]*\)", " ", line)
        if "(" in line or ")" in line:
            raise InkSliceError(where, f"line {no}: unbalanced parenthesis")
        if ";" in line:
            comments.append(line.split(";", 1)[1].strip())
            line = line.split(";", 1)[0]
        line = line.strip()
        if not line:
            continue
        if ended:
            raise InkSliceError(where, f"line {no}: text after the program end (M2/M30)")
        words = _WORD.findall(line)
        rest = _WORD.sub("", line).strip()
        if rest:
            raise InkSliceError(where, f"line {no}: cannot read {rest!r} in {raw.strip()!r}")
        axes = {}
        motion = None
        for letter, val in words:  # T before M6 wherever it stands on the line
            if letter.upper() == "T":
                selected = int(float(val))
        for letter, val in words:
            L = letter.upper()
            v = float(val)
            if L in "NOSTH":
                continue  # H: the tool-length offset's number (G43 Hn)
            if L == "G":
                g = int(round(v * 10)) / 10
                if g in (0, 1):
                    motion = int(g)
                elif g == 90:
                    absolute = True
                elif g == 91:
                    absolute = False
                elif g == 20:
                    scale = 25.4
                elif g == 21:
                    scale = 1.0
                elif g in (2, 3):
                    raise InkSliceError(
                        where, f"line {no}: arcs (G{int(g)}) are not supported by the verifier"
                    )
                elif g in _IGNORED_G or g in (43, 64):
                    pass
                else:
                    raise InkSliceError(where, f"line {no}: unsupported G{val}")
            elif L == "M":
                m = int(v)
                if m in (2, 30):
                    ended = True
                elif m == 6:
                    if selected is None:
                        raise InkSliceError(where, f"line {no}: tool change M6 with no tool selected (T)")
                    spindle = selected
                elif m not in _IGNORED_M:
                    raise InkSliceError(where, f"line {no}: unsupported M{val}")
            elif L == "F":
                if v <= 0:
                    raise InkSliceError(where, f"line {no}: feed F{val} must be > 0")
                feed = v * scale
            elif L in "XYZ":
                axes["XYZ".index(L)] = v * scale
            elif L == "P":
                continue  # G64 P tolerance
            else:
                raise InkSliceError(where, f"line {no}: unsupported word {letter}{val}")
        if motion is not None:
            mode = motion
        if axes:
            if mode is None:
                raise InkSliceError(where, f"line {no}: coordinates with no G0/G1 in effect")
            if mode == 1 and feed is None:
                raise InkSliceError(where, f"line {no}: G1 with no feed rate set (F)")
            for ax, v in axes.items():
                if absolute:
                    pos[ax] = v
                else:
                    if np.isnan(pos[ax]):
                        raise InkSliceError(where, f"line {no}: incremental move from an unknown position")
                    pos[ax] += v
            kinds.append(mode)
            pts.append(tuple(pos))
            feeds.append(feed if mode == 1 else np.nan)
            lines.append(no)
            tools.append(spindle)
    if not kinds:
        raise InkSliceError(where, "has no moves")
    return Parsed(
        np.array(kinds),
        np.array(pts, float),
        np.array(feeds, float),
        np.array(lines),
        comments,
        np.array(tools, int),
    )
