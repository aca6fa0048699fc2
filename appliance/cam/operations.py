"""A job of several operations and tools: plan each, post them as one program
(or one file per tool), name the files.

A job lists its operations in order, each with a tool from the tool table
(tools.py):

    rough T1, finish T2, rest T3          (the default three-tool job)
    finish T2 steep                       (steep and shallow finishing, waterline.py)
    finish T2                             (zig-zag finishing, zigzag.py)

rough   z-level roughing of the block from the stock top down to the part
        plus 0.3 mm (roughing.py);
finish  the finishing pass at the requested scallop: zig-zag, or `steep`
        (waterlines on walls steeper than the steep angle, zig-zag on the rest);
rest    after the previous finish or rest with a larger tool, this smaller one
        cuts only where that one could not reach (waterline.plan_rest).

Posting (why it differs by controller):
* LinuxCNC, Mach3/4 and Fanuc change tools themselves: one program, each
  tool's section starting `Tn M6` then `G43 Hn` (the controller adds that
  tool's length from its own table, so program Z stays the tool tip for every
  tool) and its own spindle speed; the header lists every tool as
  `inkslice tool n: ...` so `inkslice verify` simulates each with its cutter.
* GRBL has no tool changer and no tool table (M6 is not GRBL): one file per
  tool, each starting with a comment naming the tool and an M0 pause to put it
  in and touch off Z before the file runs on.
* The dissertation's format has no tools at all: it stays one file, the
  surface points, as before.

File names carry the job, operation, tool and dialect:
`<job>-finish-ball6-grbl.nc`; a program of several operations joins them:
`<job>-rough-flat6-finish-ball6-rest-ball2-linuxcnc.nc`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import SettingError
from ..surface.heightmap import HeightMap
from .cutters import Cutter
from .feeds import DEFAULT_MATERIAL
from .limits import DEFAULT_MACHINE, Machine, check_envelope, limit_feeds
from .posts import comment_lines, finish_lines, gcode_number, get_dialect, header_lines, motion_lines
from .program import DEFAULT_CLEARANCE, build_program, check_frame
from .roughing import RoughSettings, roughing
from .sampling import Sampler, check_heightmap
from .seed import seed_gcode
from .tools import Tool, one_line_items
from .waterline import DEFAULT_STEEP_DEG, SteepSettings, plan_rest
from .waterline import plan as steep_plan
from .zigzag import FinishSettings, finishing

OPERATION_KINDS = ("rough", "finish", "rest")
STRATEGIES = ("zigzag", "steep")
DEFAULT_OPERATIONS = "rough T1, finish T2 steep, rest T3"
ROUGH_ABOVE_PART = 2.0  # mm: the raw block's top above the part's, unless given


@dataclass(frozen=True)
class Operation:
    kind: str
    tool: Tool
    strategy: str = "zigzag"

    @property
    def label(self) -> str:
        return f"{self.kind}-{self.tool.name}"


_OP = re.compile(r"(rough|finish|rest)\s+T(\d+)(?:\s+(zigzag|steep))?", re.I)


def parse_operations(text: str, tools: dict) -> list:
    """'rough T1, finish T2 steep, rest T3' -> [Operation]; tools: {number: Tool}."""
    ops: list[Operation] = []
    form = (
        f"write each as KIND Tn [zigzag|steep], KIND one of {', '.join(OPERATION_KINDS)}, "
        "e.g. 'rough T1, finish T2, rest T3'"
    )
    for m in one_line_items(text, ",", _OP, "operations", form):
        part = m.group(0)
        kind, n, strategy = m.group(1).lower(), int(m.group(2)), (m.group(3) or "zigzag").lower()
        if n not in tools:
            raise SettingError(
                "operations",
                f"{part!r}: tool {n} is not in the tool table "
                f"(tools {', '.join(str(k) for k in sorted(tools))})",
            )
        if kind == "rest":
            before = [o for o in ops if o.kind in ("finish", "rest")]
            if not before:
                raise SettingError("operations", f"{part!r}: rest machining needs a finish before it")
            if tools[n].cutter.radius >= before[-1].tool.cutter.radius:
                raise SettingError(
                    "operations",
                    f"{part!r}: the rest tool {tools[n].name} must be smaller than "
                    f"{before[-1].tool.name} before it",
                )
        ops.append(
            Operation(
                kind, tools[n], strategy if kind == "finish" else ("steep" if kind == "rest" else "zigzag")
            )
        )
    if not ops:
        raise SettingError("operations", "no operations given")
    return ops


@dataclass
class Planned:
    op: Operation
    runs: list
    notes: list = field(default_factory=list)


def plan_operations(
    hm: HeightMap,
    ops: list,
    *,
    scallop: float = 0.05,
    steep_deg: float = DEFAULT_STEEP_DEG,
    stock_top: float | None = None,
    resolution: float = 0.1,
) -> tuple:
    """(list of Planned, stock top): every operation's tool-tip runs."""
    check_heightmap(hm)
    sampler = Sampler(hm, edge_step=resolution / 2)
    top = sampler.z_max + ROUGH_ABOVE_PART if stock_top is None else float(stock_top)
    out: list[Planned] = []
    larger: Cutter | None = None
    for op in ops:
        c = op.tool.cutter
        res = min(resolution, c.radius / 3)
        if op.kind == "rough":
            rs = RoughSettings(c, top)
            runs = roughing(sampler, rs)
            notes = [
                f"{_tn(op.tool)}roughing from Z {top:g}, step-down {rs.stepdown:g} mm, stepover "
                f"{rs.stepover_mm:g} mm, stock to leave {rs.leave:g} mm"
            ]
        elif op.kind == "finish" and op.strategy == "zigzag":
            fin = finishing(sampler, FinishSettings(c, scallop=scallop, resolution=res))
            runs = fin.runs
            notes = [f"{_tn(op.tool)}finishing zig-zag, scallop {scallop:g} mm, {len(fin.passes)} passes"]
        elif op.kind == "finish":
            p = steep_plan(sampler, SteepSettings(c, scallop, steep_deg, resolution=res))
            runs, notes = p.runs, [_tn(op.tool) + n for n in p.notes]
        else:
            if larger is None:  # parse_operations puts a finish before every rest
                raise SettingError("operations", "rest machining needs a finish before it")
            p = plan_rest(sampler, SteepSettings(c, scallop, steep_deg, resolution=res), larger)
            runs, notes = p.runs, [_tn(op.tool) + n for n in p.notes]
        if op.kind in ("finish", "rest"):
            larger = c
        out.append(Planned(op, runs, notes))
    return out, top


@dataclass
class Posted:
    name: str  # file name
    text: str
    programs: list  # [(Tool, Program)] in order, for the preview
    runtime_s: float


def _groups(planned):
    """Consecutive operations with the same tool: one tool section."""
    groups = []
    for p in planned:
        if groups and groups[-1][0].op.tool.number == p.op.tool.number:
            groups[-1].append(p)
        else:
            groups.append([p])
    return groups


def file_name(job: str, ops, dialect: str) -> str:
    stem = "-".join(f"{o.kind}-{o.tool.name}" for o in ops)
    return f"{_safe(job)}-{stem}-{dialect}.nc"


def _safe(name):
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).strip("._") or "job"


def post_operations(
    planned: list,
    stock_top: float,
    dialect: str,
    *,
    job: str = "job",
    material: str = DEFAULT_MATERIAL,
    clearance: float = DEFAULT_CLEARANCE,
    z_offset: float = 0.0,
    machine: Machine = DEFAULT_MACHINE,
    chord: float = 0.002,
    hm: HeightMap | None = None,
) -> list:
    """[Posted]: one program for a tool-changing controller, one file per tool for GRBL."""
    if dialect == "dissertation":
        if hm is None:
            raise SettingError("dialect", "the dissertation format needs the height map")
        text = seed_gcode(hm)
        return [Posted(f"{_safe(job)}-finish-dissertation.nc", text, [], float("nan"))]
    d = get_dialect(dialect)
    check_frame(clearance, z_offset)
    sections = []  # (tools' ops, [(Tool, Program, runtime)])
    for group in _groups(planned):
        tool = group[0].op.tool
        cond = tool.conditions(material)
        progs = []
        for p in group:
            if not p.runs:
                continue
            prog = build_program(
                p.runs, tool.cutter, cond, stock_top, f"{p.op.kind} T{tool.number}", clearance, z_offset
            )
            check_envelope(prog, machine)
            limit_feeds(prog, machine)
            progs.append((tool, prog, prog.runtime(machine.rapid)))
        if progs:
            sections.append(([p.op for p in group], progs, [n for p in group for n in p.notes]))
    if not sections:
        raise SettingError("operations", "no operation has anything to cut")
    if len(sections) > 1 and any(ops[0].tool.number == 0 for ops, _, _ in sections):
        raise SettingError("operations", "a job of several tools takes them from the tool table")
    if dialect == "grbl":
        return [_post_section(d, ops, progs, notes, chord, job, pause=True) for ops, progs, notes in sections]
    return [_post_changer(d, sections, chord, job)]


def _head(progs, runtime, z_offset, safe_z):
    return [
        f"Z frame: program Z = height above the base top + {z_offset:.3f} mm work offset",
        f"inkslice z_offset: {z_offset:.4f}",
        f"safe Z {safe_z:.3f}",
        f"estimated run time {runtime / 60:.1f} min",
    ]


def _post_section(d, ops, progs, notes, chord, job, pause):
    """GRBL: one tool's file, opening with the tool to put in and an M0 pause."""
    tool, first, _ = progs[0]
    runtime = sum(rt for _, _, rt in progs)
    out = comment_lines(
        d, f"tool change: put in {_tn(tool)}{tool.cutter.describe()}, touch off Z, then resume"
    ) + ["M0"]
    out += comment_lines(d, f"InkSlice {' + '.join(o.kind for o in ops)} with {_tn(tool)}{tool.name}")
    for h in header_lines(first, runtime, notes)[1:]:
        out += comment_lines(d, h)
    out += [s.format(chord=gcode_number(chord, d.decimals)) for s in d.start]
    out.append(f"M3 S{first.rpm:.0f}")
    for _, prog, _ in progs:
        out += motion_lines(prog, d)
    out += ["M5", "M30"]
    return Posted(file_name(job, ops, d.name), finish_lines(d, out), [(t, p) for t, p, _ in progs], runtime)


def _post_changer(d, sections, chord, job):
    """LinuxCNC, Mach3, Fanuc: one program; Tn M6 and G43 Hn at each tool."""
    all_ops = [o for ops, _, _ in sections for o in ops]
    progs = [(t, p, rt) for _, ps, _ in sections for t, p, rt in ps]
    runtime = sum(rt for _, _, rt in progs)
    first = progs[0][1]
    safe = max(p.safe_z for _, p, _ in progs)
    out = comment_lines(
        d, "InkSlice job: " + ", ".join(f"{o.kind} {_tn(o.tool)}{o.tool.name}" for o in all_ops)
    )
    seen = set()
    for t, _, _ in progs:
        if t.number not in seen:
            seen.add(t.number)
            # a cutter not from the tool table (number 0) is the only one: no change, as before
            out += comment_lines(
                d,
                f"inkslice tool {t.number}: {t.cutter.describe()}"
                if t.number
                else f"inkslice cutter: {t.cutter.describe()}",
            )
    for h in _head(progs, runtime, first.z_offset, safe):
        out += comment_lines(d, h)
    for _, _, notes in sections:
        for n in notes:
            out += comment_lines(d, n)
    out += [s.format(chord=gcode_number(chord, d.decimals)) for s in d.start]
    for ops, ps, _ in sections:
        tool = ps[0][0]
        out += comment_lines(d, f"{' + '.join(o.kind for o in ops)}: {_tn(tool)}{tool.cutter.describe()}")
        if tool.number:
            out += [f"T{tool.number} M6", f"G43 H{tool.number}"]
        out.append(f"M3 S{ps[0][1].rpm:.0f}")
        for _, prog, _ in ps:
            out += motion_lines(prog, d)
        out.append("M5")
    out += (["G49"] if any(t.number for t, _, _ in progs) else []) + ["M30"]
    return Posted(
        file_name(job, all_ops, d.name), finish_lines(d, out), [(t, p) for t, p, _ in progs], runtime
    )


def _tn(tool):
    return f"T{tool.number} " if tool.number else ""


def tool_cutters(parsed) -> dict:
    """{tool number: Cutter} from a job program's `inkslice tool n:` header lines."""
    from .cutters import Cutter

    out = {}
    for c in parsed.comments:
        m = re.match(r"inkslice tool (\d+):\s*(\w+)\s+D([\d.]+)\s+CR([\d.]+)\s+FL([\d.]+)", c, re.I)
        if m:
            out[int(m.group(1))] = Cutter(float(m.group(3)), float(m.group(4)), float(m.group(5)))
    return out
