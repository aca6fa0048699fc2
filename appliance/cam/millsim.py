"""Simulated milling on a height-map stock, and what it says about a program.

The stock is a height field on a fine lattice (0.1 mm by default). Every
move, G1 and G0 alike, sweeps the cutter along its straight segment and
lowers the stock to the swept cutter's lower surface. For a segment from A
to B (tip positions, c(t) = A + t (B - A)) and a cell q:

    stock(q) <- min(stock(q),  min over t in [0, 1] of  c_z(t) + h(|q - c_xy(t)|))

over the t where q is under the cutter (|q - c_xy(t)| <= R: an interval
found from a quadratic). The function of t is convex (h is convex and
increasing, |q - c_xy(t)| is convex, c_z is linear), so its minimum on the
interval is found exactly: in closed form for a ball (the stationary point
of the swept sphere, clamped) and a flat end (an end of the interval), by a
golden-section search for a bull nose. So the sweep is continuous along the
segment, not a row of stamped cutters, and the only sampling is the stock
lattice itself. A rapid that lowers the stock is a crash and is reported.

What is reported (all in mm, vertical):
* gouge: max(design - stock) over the part: how deep the program cut into it;
* scallop = stock - max(design, opening), max and mean, over the cells where
  the cutter can reach: cells where the cutter's opening of the design (the
  stock an infinitely fine stepover would leave) is within `reach_tol` of the
  design (tool positions up to a radius past the outline count: a program
  that runs off it onto the base reaches the rim from there), and at least
  `edge_band` inside the footprint's edge (default 0: all of it). Measured from
  the opening, not the design: the opening's own residue (<= reach_tol) is
  set by the cutter's size, not the stepover. Concave regions
  tighter than the cutter, and the walls of steps, are excluded there and
  counted separately as unreachable area;
* uncut area: part cells left more than `uncut_tol` above the design, also as
  a fraction of the cells the cutter can reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .cutters import Cutter
from .gcodeparse import Parsed
from .opening import REACH_TOL, Opening
from .sampling import Sampler
from .segments import min_over_segment

# a rapid that lowers the stock by more than this is reported as a crash (grazing
# contacts at the cutter's rim round to a few microns and are not crashes)
CRASH_DEPTH = 0.002


@dataclass
class Stock:
    xs: np.ndarray
    ys: np.ndarray
    z: np.ndarray


def new_stock(sampler: Sampler, resolution: float, top: float, pad: float = 0.0) -> Stock:
    x0, x1, y0, y1 = sampler.bounds
    xs = np.arange(x0 - pad, x1 + pad + resolution / 2, resolution)
    ys = np.arange(y0 - pad, y1 + pad + resolution / 2, resolution)
    return Stock(xs, ys, np.full((ys.size, xs.size), float(top)))


def sweep(stock: Stock, cutter: Cutter, A, B) -> float:
    """Lower the stock along one segment; returns the deepest lowering (mm)."""
    R = cutter.radius
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    xs, ys = stock.xs, stock.ys
    i0 = np.searchsorted(xs, min(A[0], B[0]) - R, "left")
    i1 = np.searchsorted(xs, max(A[0], B[0]) + R, "right")
    j0 = np.searchsorted(ys, min(A[1], B[1]) - R, "left")
    j1 = np.searchsorted(ys, max(A[1], B[1]) + R, "right")
    if i1 <= i0 or j1 <= j0:
        return 0.0
    dx = xs[None, i0:i1] - A[0]
    dy = ys[j0:j1, None] - A[1]
    w = B - A
    val = min_over_segment(cutter, dx, dy, w[0], w[1], w[2], A[2])
    sub = stock.z[j0:j1, i0:i1]
    new = val
    drop = float(np.max(sub - new, initial=0.0))
    np.minimum(sub, new, out=sub)
    return drop


@dataclass
class SimResult:
    stock: Stock
    crashes: int  # rapids that cut
    first_crash_line: int | None
    moves: int


def simulate(parsed: Parsed, cutter: Cutter, stock: Stock, z_zero: float = 0.0) -> SimResult:
    """Run every move of a parsed program over the stock. z_zero: object height of program Z0.

    Feed moves are swept in batches (the stock is a minimum, so their order
    does not matter); each rapid is swept on its own, in order, so a rapid
    that meets stock left by earlier moves is caught as a crash.
    """
    xyz = parsed.xyz.copy()
    xyz[:, 2] += z_zero
    # fill axes never set with the next known value (the first move may set only Z)
    for ax in range(3):
        col = xyz[:, ax]
        known = np.flatnonzero(~np.isnan(col))
        if known.size == 0:
            raise ValueError("program never sets " + "XYZ"[ax])
        col[: known[0]] = col[known[0]]
    starts = np.vstack([xyz[:1], xyz[:-1]])
    crashes, first = 0, None
    k, n = 0, len(xyz)
    while k < n:
        if parsed.kind[k] == 0:
            if sweep(stock, cutter, starts[k], xyz[k]) > CRASH_DEPTH:
                crashes += 1
                first = first or int(parsed.line[k])
            k += 1
            continue
        e = k
        while e < n and parsed.kind[e] == 1:
            e += 1
        sweep_many(stock, cutter, starts[k:e], xyz[k:e])
        k = e
    return SimResult(stock, crashes, first, len(xyz))


def sweep_many(stock: Stock, cutter: Cutter, A, B, budget=3_000_000):
    """Sweep many segments at once: every (segment, cell of its box) pair is one element."""
    R = cutter.radius
    xs, ys = stock.xs, stock.ys
    nxs = xs.size
    i0 = np.searchsorted(xs, np.minimum(A[:, 0], B[:, 0]) - R, "left")
    i1 = np.searchsorted(xs, np.maximum(A[:, 0], B[:, 0]) + R, "right")
    j0 = np.searchsorted(ys, np.minimum(A[:, 1], B[:, 1]) - R, "left")
    j1 = np.searchsorted(ys, np.maximum(A[:, 1], B[:, 1]) + R, "right")
    wi = np.maximum(i1 - i0, 0)
    cnt = wi * np.maximum(j1 - j0, 0)
    flat = stock.z.reshape(-1)
    s = 0
    while s < len(A):
        e = s + max(1, int(np.searchsorted(np.cumsum(cnt[s:]), budget, "right")))
        c = cnt[s:e]
        tot = int(c.sum())
        if tot:
            seg = np.repeat(np.arange(s, e), c)
            off = np.arange(tot) - np.repeat(np.cumsum(c) - c, c)
            li, lj = off % wi[seg], off // wi[seg]
            ci, cj = i0[seg] + li, j0[seg] + lj
            a = A[seg]
            w = B[seg] - a
            val = min_over_segment(
                cutter, xs[ci] - a[:, 0], ys[cj] - a[:, 1], w[:, 0], w[:, 1], w[:, 2], a[:, 2]
            )
            fin = np.isfinite(val)
            np.minimum.at(flat, cj[fin] * nxs + ci[fin], val[fin])
        s = e


@dataclass
class Report:
    gouge: float
    gouge_at: tuple
    scallop_max: float
    scallop_mean: float
    scallop_at: tuple
    uncut_area: float
    uncut_fraction: float
    unreachable_area: float
    part_area: float
    measured_area: float
    crashes: int
    first_crash_line: int | None
    deviation: np.ndarray
    part: np.ndarray
    measured: np.ndarray
    uncut_reachable: float = 0.0  # fraction of the cells the cutter can reach left uncut

    def lines(self):
        out = [
            f"gouge (deepest cut below the design): {self.gouge:.4f} mm at x={self.gouge_at[0]:.2f} y={self.gouge_at[1]:.2f}",
            f"scallop: max {self.scallop_max:.4f} mm at x={self.scallop_at[0]:.2f} y={self.scallop_at[1]:.2f}, "
            f"mean {self.scallop_mean:.4f} mm over {self.measured_area:.0f} mm^2 the cutter can reach",
            f"unreachable by the cutter (excluded): {self.unreachable_area:.1f} mm^2",
            f"uncut area: {self.uncut_area:.1f} mm^2 ({100 * self.uncut_fraction:.2f} % of {self.part_area:.0f} mm^2, "
            f"{100 * self.uncut_reachable:.2f} % of the area the cutter can reach)",
            f"rapids that cut stock: {self.crashes}"
            + (f" (first at line {self.first_crash_line})" if self.crashes else ""),
        ]
        return out


def report(
    sampler: Sampler,
    cutter: Cutter,
    sim: SimResult,
    reach_tol=REACH_TOL,
    edge_band=0.0,
    uncut_tol=0.1,
    reach_resolution=0.0,
) -> Report:
    st = sim.stock
    X, Y = np.meshgrid(st.xs, st.ys)
    design = sampler.z(X, Y)
    part = sampler.on_part(X, Y)
    dev = st.z - design
    r = float(st.xs[1] - st.xs[0]) if st.xs.size > 1 else 1.0
    cell = r * r
    # distance to the footprint's edge, for the edge band
    inner = ndimage.distance_transform_edt(np.pad(part, 1), sampling=r)[1:-1, 1:-1]
    # reachability from the opening (opening.py), on a lattice at least as coarse as the stock's
    d = max(reach_resolution, r)
    # positions up to a radius past the outline, where a program finishing the rim runs
    op = Opening.over(sampler, cutter, d, st.xs[0], st.ys[0], st.xs[-1], st.ys[-1], pad=cutter.radius)
    above, reach = op.above(st.z, design, X, Y, reach_tol)
    measured = part & reach & (inner >= edge_band)
    g = np.where(part, -dev, -np.inf)
    k = np.unravel_index(int(np.argmax(g)), g.shape)
    gouge = max(float(g[k]), 0.0)
    # scallop: what the stepover left above what the cutter can reach at all
    sc = np.where(measured, above, -np.inf)
    ks = np.unravel_index(int(np.argmax(sc)), sc.shape)
    smax = float(sc[ks]) if measured.any() else float("nan")
    smean = float(np.mean(np.maximum(above[measured], 0))) if measured.any() else float("nan")
    uncut = part & (dev > uncut_tol)
    return Report(
        gouge,
        (float(X[k]), float(Y[k])),
        smax,
        smean,
        (float(X[ks]), float(Y[ks])),
        float(uncut.sum() * cell),
        float(uncut.sum() / max(part.sum(), 1)),
        float((part & ~reach).sum() * cell),
        float(part.sum() * cell),
        float(measured.sum() * cell),
        sim.crashes,
        sim.first_crash_line,
        dev,
        part,
        measured,
        float((uncut & reach).sum() / max((part & reach).sum(), 1)),
    )


def deviation_png(rep: Report, scallop_scale: float = 0.02, max_px: int = 1000) -> bytes:
    """The deviation map as a PNG: red = gouge, white = on the design, blue = material left.

    Grey: off the part; yellow: cells the cutter cannot reach (excluded from the scallop).
    North (+y) is up.
    """
    import cv2

    dev, part = rep.deviation, rep.part
    h, w = dev.shape
    img = np.zeros((h, w, 3), np.float64)
    pos = np.clip(dev / scallop_scale, 0, 1)
    neg = np.clip(-dev / max(scallop_scale / 4, 1e-6), 0, 1)
    # BGR
    img[..., 0] = 255
    img[..., 1] = 255 * (1 - pos)
    img[..., 2] = 255 * (1 - pos)
    red = neg > 0
    img[red, 0] = 255 * (1 - neg[red])
    img[red, 1] = 255 * (1 - neg[red])
    img[red, 2] = 255
    unreach = part & ~rep.measured
    img[unreach & ~red] = (120, 230, 240)
    img[~part] = (128, 128, 128)
    img = np.flipud(img).astype(np.uint8)
    s = max(1, int(np.ceil(max(h, w) / max_px)))
    img = img[::s, ::s]
    bar = np.full((48, img.shape[1], 3), 255, np.uint8)
    txt = f"gouge {rep.gouge:.4f}  scallop max {rep.scallop_max:.4f} mm  blue=+{scallop_scale:g} red=-{scallop_scale / 4:g}"
    cv2.putText(
        bar,
        txt,
        (6, 30),
        cv2.FONT_HERSHEY_SIMPLEX,
        max(0.3, min(0.6, img.shape[1] / 1400)),
        (0, 0, 0),
        1,
        cv2.LINE_AA,
    )
    ok, buf = cv2.imencode(".png", np.vstack([img, bar]))
    return buf.tobytes()
