"""The two things users ask of this room, as plain functions the commands call.

`finishing_gcode` / `roughing_gcode`: height map in, G-code text and a small
summary out. `verify_gcode`: G-code text and height map in, a verification
report (and its deviation map) out. No files: the command modules read and
write them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InkSliceError, SettingError, check_mm
from ..surface.confidence import header_notes
from ..surface.heightmap import HeightMap
from ..surface.pools import held_notes
from ..surface.uncertainty import DEFAULT_UNCERTAIN_MM
from .cutters import Cutter, parse_cutter
from .feeds import DEFAULT_MATERIAL, conditions
from .gcodeparse import parse_gcode
from .limits import DEFAULT_MACHINE, Machine, check_envelope, limit_feeds
from .millsim import new_stock, report, simulate
from .opening import REACH_TOL
from .posts import DEFAULT_DIALECT, render
from .program import DEFAULT_CLEARANCE, build_program, check_frame
from .roughing import RoughSettings, roughing
from .sampling import Sampler, check_heightmap
from .seed import seed_gcode
from .zigzag import FinishSettings, finishing

# The lattice a plan or a simulation works on, at its resolution over the part's
# bounding box: beyond this the run would take gigabytes (and hours), so it is refused
# with the setting to change, before anything that size is allocated.
MAX_WORK_CELLS = 40_000_000


def check_work(hm: HeightMap, resolution: float, setting: str):
    check_mm(setting, resolution)
    wx, wy = float(hm.x[-1] - hm.x[0]), float(hm.y[-1] - hm.y[0])
    cells = (wx / resolution + 1) * (wy / resolution + 1)
    if cells > MAX_WORK_CELLS:
        raise SettingError(
            setting,
            f"{resolution:g} mm over a {wx:.1f} x {wy:.1f} mm part is a lattice of "
            f"{cells:.3g} cells, more than {MAX_WORK_CELLS:.3g}: use a coarser {setting}",
        )


@dataclass
class Job:
    text: str
    runtime_s: float
    summary: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Setup:
    """What every job takes besides its plan: the cutting conditions (None: from the material)
    and where the program sits on the machine. The jobs below take these as keywords."""

    material: str = DEFAULT_MATERIAL
    feed: float | None = None
    plunge: float | None = None
    rpm: float | None = None
    clearance: float = DEFAULT_CLEARANCE
    z_offset: float = 0.0
    machine: Machine = DEFAULT_MACHINE


def _prepare(hm, settings, setup: Setup):
    """Every check a plan's inputs get before planning (which takes seconds to minutes), then
    the cutting conditions and the sampler the plan reads the surface through."""
    cond = conditions(settings.cutter, setup.material, feed=setup.feed, plunge=setup.plunge, rpm=setup.rpm)
    settings.check()
    check_work(hm, settings.resolution, "resolution")
    check_frame(setup.clearance, setup.z_offset)
    return cond, Sampler(hm, edge_step=settings.resolution / 2)


def _summary(cond, slowed, text, **plan) -> dict:
    """A job's summary: what the plan made, then the conditions it cuts with."""
    return {
        **plan,
        "feed": cond.feed,
        "plunge": cond.plunge,
        "rpm": cond.rpm,
        "slowed_moves": slowed,
        "lines": text.count("\n"),
    }


def _post(hm, runs, cutter, cond, stock_top, title, dialect, setup: Setup, chord, notes):
    prog = build_program(runs, cutter, cond, stock_top, title, setup.clearance, setup.z_offset)
    check_envelope(prog, setup.machine)
    slowed = limit_feeds(prog, setup.machine)
    rt = prog.runtime(setup.machine.rapid)
    text = render(prog, dialect, rt, chord, notes)
    return prog, text, rt, slowed


def finishing_gcode(hm: HeightMap, settings: FinishSettings, *, dialect=DEFAULT_DIALECT, **kw) -> Job:
    return finishing_gcodes(hm, settings, (dialect,), **kw)[dialect]


def finishing_gcodes(
    hm: HeightMap,
    settings: FinishSettings,
    dialects,
    *,
    stock_top=None,
    uncertain_mm=DEFAULT_UNCERTAIN_MM,
    **setup,
) -> dict:
    """One finishing plan written in several dialects: {dialect: Job}. A map that carries
    its uncertainty has its low-confidence regions (over `uncertain_mm`) named in the header.
    `setup`: the keywords of Setup."""
    check_heightmap(hm)
    su = Setup(**setup)
    jobs = {}
    if "dissertation" in dialects:
        text = seed_gcode(hm)
        jobs["dissertation"] = Job(text, float("nan"), {"dialect": "dissertation", "lines": text.count("\n")})
    ours = [d for d in dialects if d != "dissertation"]
    if not ours:
        return jobs
    cond, sampler = _prepare(hm, settings, su)
    settings, clipped = _within_travel(hm, settings, su.machine)
    fin = finishing(sampler, settings)
    top = sampler.z_max + settings.leave if stock_top is None else float(stock_top)
    target = (
        f"scallop {settings.scallop:g} mm"
        if settings.stepover is None
        else f"stepover {settings.stepover:g} mm"
    )
    notes = [
        f"finishing zig-zag at {settings.angle:g} deg, {target}, {len(fin.passes)} passes, "
        f"stock to leave {settings.leave:g} mm, margin {fin.margin:g} mm"
    ]
    if clipped:
        notes.append(clipped)
    notes += header_notes(hm, uncertain_mm) + held_notes(hm)
    so = fin.stepovers
    for d in ours:
        prog, text, rt, slowed = _post(
            hm,
            fin.runs,
            settings.cutter,
            cond,
            top,
            "InkSlice finishing program",
            d,
            su,
            settings.chord,
            notes,
        )
        summary = _summary(
            cond,
            slowed,
            text,
            passes=int(len(fin.passes)),
            runs=len(fin.runs),
            points=int(sum(len(r) for r in fin.runs)),
            stepover_min=float(so.min()) if so.size else 0.0,
            stepover_max=float(so.max()) if so.size else 0.0,
        )
        jobs[d] = Job(text, rt, summary)
    return jobs


def _within_travel(hm: HeightMap, settings: FinishSettings, machine: Machine):
    """-> (settings, note): the margin the passes run off the outline by, cut to what the
    machine's X and Y travel leave beside the map on its tightest side (one margin for every
    side: a part scanned near the travel's edge gets its rim finished that far, not no
    program at all); note is '' when nothing was cut."""
    (xlo, xhi), (ylo, yhi) = machine.travel[0], machine.travel[1]
    room = min(hm.x.min() - xlo, xhi - hm.x.max(), hm.y.min() - ylo, yhi - hm.y.max())
    if settings.margin <= 0 or room >= settings.margin:
        return settings, ""
    margin = max(room - 0.01, 0.0)
    note = (
        f"the passes run off the outline by {margin:.3f} mm, not {settings.margin:.3f}: the machine's "
        "travel ends there (the rim beyond is left)"
    )
    return replace(settings, margin=margin), note


def roughing_gcode(hm: HeightMap, settings: RoughSettings, *, dialect=DEFAULT_DIALECT, **setup) -> Job:
    """`setup`: the keywords of Setup."""
    check_heightmap(hm)
    su = Setup(**setup)
    if dialect == "dissertation":
        raise SettingError("dialect", "the dissertation format has no roughing; choose another dialect")
    cond, sampler = _prepare(hm, settings, su)
    runs = roughing(sampler, settings)
    notes = [
        f"z-level roughing from Z {settings.stock_top:g}, step-down {settings.stepdown:g} mm, "
        f"stepover {settings.stepover_mm:g} mm, stock to leave {settings.leave:g} mm"
    ]
    prog, text, rt, slowed = _post(
        hm,
        runs,
        settings.cutter,
        cond,
        settings.stock_top,
        "InkSlice roughing program",
        dialect,
        su,
        settings.chord,
        notes,
    )
    return Job(text, rt, _summary(cond, slowed, text, runs=len(runs)))


def cutter_from_program(parsed, default=None) -> Cutter:
    """The cutter our header names (`inkslice cutter: ball D6.000 CR3.000 FL48.0`), else `default`."""
    meta = parsed.meta("inkslice cutter")
    if meta:
        try:
            parts = meta.upper().split()
            vals = {p[:2]: float(p[2:]) for p in parts[1:] if p[:2] in ("CR", "FL")}
            dia = float(parts[1][1:])
            return Cutter(dia, vals["CR"], vals.get("FL", 8 * dia))
        except (ValueError, KeyError, IndexError):
            raise InkSliceError("G-code", f"cannot read the cutter header {meta!r}") from None
    if default is None:
        raise SettingError(
            "cutter", "the program does not name its cutter; name the one it was made for (e.g. ball6)"
        )
    return parse_cutter(default) if isinstance(default, str) else default


def verify_gcode(
    text: str,
    hm: HeightMap,
    *,
    cutter=None,
    z_zero=None,
    resolution=0.1,
    reach_tol=REACH_TOL,
    edge_band=0.0,
    uncut_tol=0.1,
    where="G-code",
):
    """Simulate `text` over a flat block and compare with `hm`. Returns (Report, summary dict).

    z_zero: object height of program Z0 (None: from our header, else 0). The
    block's top is the part's top + 1 mm, or the program's safe height if lower.
    """
    check_heightmap(hm)
    check_mm("resolution", resolution)
    check_mm("reach tolerance", reach_tol)
    check_mm("edge band", edge_band, zero_ok=True)
    check_mm("uncut tolerance", uncut_tol, zero_ok=True)
    check_work(hm, resolution, "resolution")
    parsed = parse_gcode(text, where)
    for ax, name in enumerate("XYZ"):
        if np.all(np.isnan(parsed.xyz[:, ax])):
            # a 2-D program (or one in another axis's words) was a ValueError traceback
            raise InkSliceError(where, f"never sets {name}: there is no cutter position to simulate")
    if cutter is not None and not isinstance(cutter, Cutter):
        cutter = parse_cutter(cutter)
    from .operations import tool_cutters

    tools = tool_cutters(parsed) if cutter is None else {}
    if tools:
        spindle = parsed.tool if parsed.tool is not None else np.zeros(len(parsed.kind), int)
        missing = sorted(set(spindle.tolist()) - set(tools) - {0})
        if missing or bool((spindle == 0).all()):
            raise InkSliceError(
                where,
                f"changes to tool {missing[0] if missing else 0}, which its header "
                "does not describe (inkslice tool n: ...)",
            )
        # the report's reach is the smallest tool's: what the whole job could cut
        cut = min(tools.values(), key=lambda c: c.radius)
    else:
        cut = cutter if cutter is not None else cutter_from_program(parsed)
    if z_zero is None:
        m = parsed.meta("inkslice z_offset")
        z_zero = -float(m) if m else 0.0
    if not np.isfinite(z_zero):
        # a NaN Z0 made every Z unknown: a "program never sets Z" traceback
        raise SettingError("z zero", f"must be a number of mm or 'top', got {z_zero}")
    # edges on: the opening (what the cutter can reach at all) must see the part's
    # edge as the toolpath did, or the band along uphill edges counts as scallop
    sampler = Sampler(hm, edge_step=resolution / 2)
    top = sampler.z_max + 1.0
    stock = new_stock(sampler, resolution, top)
    if tools:
        sim = simulate_tools(parsed, tools, stock, z_zero)
    else:
        sim = simulate(parsed, cut, stock, z_zero)
    rep = report(sampler, cut, sim, reach_tol, edge_band, uncut_tol)
    desc = ", ".join(f"T{n} {c.describe()}" for n, c in sorted(tools.items())) if tools else cut.describe()
    return rep, {"cutter": desc, "moves": sim.moves, "z_zero": z_zero}


def simulate_tools(parsed, tools: dict, stock, z_zero):
    """A program of several tools on one stock: each stretch of moves with the tool that is in
    the spindle (moves before the first change, the retract to the safe height, with the first)."""
    from .gcodeparse import Parsed
    from .millsim import SimResult

    tool = parsed.tool.copy()
    first = int(tool[tool > 0][0])
    tool[tool == 0] = first
    # positions known so far carry into each stretch (its first move may set only Z)
    xyz = parsed.xyz.copy()
    for ax in range(3):
        col = xyz[:, ax]
        known = np.flatnonzero(~np.isnan(col))
        col[: known[0]] = col[known[0]]
        idx = np.where(~np.isnan(col), np.arange(col.size), 0)
        np.maximum.accumulate(idx, out=idx)
        xyz[:, ax] = col[idx]
    crashes, first_line, moves = 0, None, 0
    edges = np.flatnonzero(np.diff(tool)) + 1
    for a, b in zip(np.concatenate([[0], edges]), np.concatenate([edges, [tool.size]])):
        part = Parsed(parsed.kind[a:b], xyz[a:b], parsed.feed[a:b], parsed.line[a:b], [], tool[a:b])
        r = simulate(part, tools[int(tool[a])], stock, z_zero)
        crashes += r.crashes
        first_line = first_line or r.first_crash_line
        moves += r.moves
    return SimResult(stock, crashes, first_line, moves)
