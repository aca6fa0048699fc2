"""inkslice toolpath HEIGHTMAP -o toolpath.gcode [--rough-out rough.gcode]
inkslice toolpath JOB_FOLDER [--operations 'rough T1, finish T2 steep, rest T3'] [--dialect grbl] ...

Given a job folder (one holding heightmap.csv), the program is posted again
for it without rescanning, named for the job, operation, tool and dialect
(`<job>-finish-ball6-grbl.nc`) and written into that folder (or into -o, a
folder), with its preview JSON beside it (`.preview.json`)."""

from __future__ import annotations

from .. import atomicio, progress
from ..outputs import read_heightmap_csv
from ._flags import flags

NAME = "toolpath"
ORDER = 30
HELP = "turn heightmap.csv into a cutter-compensated finishing (and roughing) G-code program"
PROGRESS = True  # cli.py shows the stages below


def add_arguments(p):
    from ..cam.feeds import DEFAULT_MATERIAL, MATERIALS
    from ..cam.posts import DEFAULT_DIALECT, DIALECT_NAMES

    p.add_argument("heightmap", help="heightmap.csv (x,y,z in mm, z above the base top)")
    p.add_argument(
        "-o",
        "--out",
        default=None,
        help="finishing program to write (with a job folder or "
        "--operations: the folder to write the named programs into; default the job folder)",
    )
    g = p.add_argument_group("cutter and material")
    g.add_argument("--cutter", default="ball6", help="ball6, flat3, bull6r1, ... (default ball6)")
    g.add_argument(
        "--flute-length",
        type=float,
        default=None,
        help="usable length below the holder, mm (default 8 x diameter)",
    )
    g.add_argument("--flutes", type=int, default=2)
    g.add_argument("--material", default=DEFAULT_MATERIAL, choices=sorted(MATERIALS))
    g.add_argument(
        "--feed", type=float, default=None, help="cutting feed, mm/min (default from the material)"
    )
    g.add_argument("--plunge-feed", type=float, default=None, help="plunge feed, mm/min")
    g.add_argument("--spindle", type=float, default=None, help="spindle speed, rpm")
    g = p.add_argument_group("finishing")
    # the same default as `process` and the daemon's setting: 0.01 took 13 min and 590 MB on the
    # blade's map here (838 passes), about an hour on a Pi
    g.add_argument("--scallop", type=float, default=0.05, help="target scallop height, mm (default 0.05)")
    g.add_argument("--stepover", type=float, default=None, help="fixed stepover, mm (instead of --scallop)")
    g.add_argument("--angle", type=float, default=0.0, help="pass direction, degrees from X (default 0)")
    g.add_argument("--resolution", type=float, default=0.1, help="point spacing along a pass, mm")
    g.add_argument(
        "--chord",
        type=float,
        default=None,
        help="chord tolerance for point reduction, mm (default: 0.002 or scallop / 20, the smaller)",
    )
    g.add_argument(
        "--margin",
        type=float,
        default=None,
        help="how far the cutter axis may go past the part's edge, mm (0..radius; default: the "
        "cutter's radius less a tenth of a step, so the rim is finished; 0 is faster and leaves it)",
    )
    g.add_argument(
        "--rim",
        action="store_true",
        help="run the passes off the outline by the cutter's radius less a tenth of a step, "
        "so the rim is finished too (the default; kept for scripts that name it)",
    )
    g.add_argument("--leave", type=float, default=0.0, help="stock to leave on the finishing pass, mm")
    g.add_argument(
        "--uncertain-mm",
        type=float,
        default=None,
        help="the header lists the height map's "
        "regions whose uncertainty exceeds this, mm (default 0.1; needs a map with uncertainty_mm)",
    )
    g.add_argument(
        "--steep",
        action="store_true",
        help="finish steep and shallow: waterlines on walls steeper than --steep-angle, zig-zag on the rest",
    )
    g.add_argument(
        "--steep-angle",
        type=float,
        default=50.0,
        help="the slope above which walls get waterline passes, degrees (default 50)",
    )
    g = p.add_argument_group("several tools (programs named <job>-<operation>-<tool>-<dialect>.nc)")
    g.add_argument(
        "--operations",
        default=None,
        help="e.g. 'rough T1, finish T2 steep, rest T3' (tools from "
        "the tool table; LinuxCNC/Mach3/Fanuc get one program with tool changes, GRBL one per tool)",
    )
    g.add_argument(
        "--tools",
        default=None,
        help="tool table: a JSON file (a list of tools) or the settings' "
        "one-line form 'T1 flat D6 FL48; T2 ball D6; T3 ball D2' (default: that table)",
    )
    g.add_argument(
        "--job", default=None, help="the job's name in the file names (default: the job folder's name)"
    )
    g.add_argument(
        "--preview",
        action="store_true",
        help="also write each program's preview JSON (always, for a job folder)",
    )
    g = p.add_argument_group("roughing (optional, written to its own program)")
    g.add_argument("--rough-out", default=None, help="also write a z-level roughing program here")
    g.add_argument("--rough-cutter", default="flat6")
    g.add_argument(
        "--stock-top",
        type=float,
        default=None,
        help="top of the raw block above the base, mm (default: part top + 2)",
    )
    g.add_argument("--stepdown", type=float, default=1.0)
    g.add_argument("--rough-leave", type=float, default=0.3)
    g.add_argument("--rough-stepover", type=float, default=None)
    g = p.add_argument_group("program and machine")
    g.add_argument("--dialect", default=DEFAULT_DIALECT, choices=DIALECT_NAMES)
    g.add_argument("--clearance", type=float, default=5.0, help="safe height above the stock top, mm")
    g.add_argument("--z-offset", type=float, default=0.0, help="work offset: program Z of the base top, mm")
    g.add_argument("--travel", default=None, help="xmin,xmax,ymin,ymax,zmin,zmax in program coordinates, mm")
    g.add_argument("--max-feed", default=None, help="fx,fy,fz, mm/min")
    g.add_argument("--rapid", type=float, default=None, help="rapid rate for the run-time estimate, mm/min")


def _machine(args):
    from ..cam.limits import Machine, parse_feeds, parse_travel

    kw = {}
    with flags({"machine travel": "--travel", "machine max feed": "--max-feed"}):
        if args.travel:
            kw["travel"] = parse_travel(args.travel)
        if args.max_feed:
            kw["max_feed"] = parse_feeds(args.max_feed)
    if args.rapid is not None:
        kw["rapid"] = args.rapid
    return Machine(**kw)


def run(args):
    from pathlib import Path

    if Path(args.heightmap).is_dir() or args.operations:
        return run_job(args)
    if args.out is None:
        from ..errors import SettingError

        raise SettingError("-o", "give the program to write (or a job folder instead of a height map)")
    from ..cam.cutters import parse_cutter
    from ..cam.jobs import finishing_gcode, roughing_gcode
    from ..cam.roughing import RoughSettings
    from ..cam.sampling import check_heightmap
    from ..cam.zigzag import RIM, FinishSettings

    atomicio.check_output_file(args.out, "-o")  # before the work, not after it
    if args.rough_out:
        atomicio.check_output_file(args.rough_out, "--rough-out")
    from ..surface.base import stand_on_base

    hm, fix = stand_on_base(read_heightmap_csv(args.heightmap))  # as `inkslice process` mills it
    check_heightmap(hm, where=args.heightmap)  # its problems named by the file
    for sentence in fix.sentences():
        print(f"note: {args.heightmap}: {sentence}")
    machine = _machine(args)
    common = dict(
        material=args.material,
        feed=args.feed,
        plunge=args.plunge_feed,
        rpm=args.spindle,
        dialect=args.dialect,
        clearance=args.clearance,
        z_offset=args.z_offset,
        machine=machine,
    )
    with flags({"cutter": "--cutter"}):
        cutter = parse_cutter(args.cutter, args.flute_length, args.flutes)
    st = FinishSettings(
        cutter,
        scallop=None if args.stepover is not None else args.scallop,
        stepover=args.stepover,
        angle=args.angle,
        resolution=args.resolution,
        chord=args.chord,
        margin=RIM if args.rim or args.margin is None else args.margin,
        leave=args.leave,
    )
    if args.rough_out:
        import numpy as np

        with flags({"cutter": "--rough-cutter"}):
            rc = parse_cutter(args.rough_cutter, args.flute_length, args.flutes)
        top = float(np.nanmax(hm.z)) + 2.0 if args.stock_top is None else args.stock_top
        rs = RoughSettings(rc, top, args.stepdown, args.rough_leave, args.rough_stepover)
        progress.stage("roughing program")
        rough = roughing_gcode(hm, rs, **common)
        _write(args.rough_out, rough.text)
        print(
            f"{args.rough_out}: roughing, {rough.summary['runs']} runs, "
            f"estimated run time {rough.runtime_s / 60:.1f} min"
        )
    if args.steep:
        return _post_named(args, hm, [_finish_op(args, cutter)], Path(args.out).parent, Path(args.out).name)
    progress.stage("finishing program")
    job = finishing_gcode(hm, st, uncertain_mm=_uncertain_mm(args), **common)
    _write(args.out, job.text)
    if args.dialect == "dissertation":
        print(f"{args.out}: dissertation format, {job.summary['lines']} lines (no cutter compensation)")
        return 0
    s = job.summary
    print(
        f"{args.out}: finishing, {s['passes']} passes, stepover {s['stepover_min']:.3f}-{s['stepover_max']:.3f} mm, "
        f"{s['lines']} lines, feed {s['feed']:.0f} mm/min, spindle {s['rpm']:.0f} rpm"
    )
    if s["slowed_moves"]:
        print(f"{s['slowed_moves']} moves slowed to the machine's axis feed limits")
    print(f"estimated run time {job.runtime_s / 60:.1f} min")
    return 0


def _uncertain_mm(args):
    import math

    from ..errors import SettingError
    from ..surface.uncertainty import DEFAULT_UNCERTAIN_MM

    if args.uncertain_mm is None:
        return DEFAULT_UNCERTAIN_MM
    if not (math.isfinite(args.uncertain_mm) and args.uncertain_mm > 0):
        raise SettingError("--uncertain-mm", f"must be a number of mm > 0, got {args.uncertain_mm}")
    return args.uncertain_mm


def _write(path, text):
    atomicio.check_output_file(path, "-o")
    atomicio.write_text(path, text)


def _tool_table(args):
    import json
    from pathlib import Path

    from ..cam.tools import default_tools, parse_tool_table
    from ..errors import InkSliceError

    if not args.tools:
        return default_tools()
    if not Path(args.tools).is_file() and args.tools.lstrip()[:1] in ("T", "t"):
        from ..cam.tools import parse_tool_text

        return parse_tool_text(args.tools)  # the settings' one-line form
    try:
        with open(args.tools, encoding="utf-8") as f:
            return parse_tool_table(json.load(f))
    except OSError as e:
        raise InkSliceError(args.tools, f"cannot read the tool table: {e.strerror}") from None
    except ValueError as e:
        raise InkSliceError(args.tools, f"not a JSON tool table: {e}") from None


def _finish_op(args, cutter, tools=None):
    """A finishing operation with `cutter`: the table's tool of that shape if there is one."""
    from ..cam.operations import Operation
    from ..cam.tools import Tool

    tools = tools or {}
    same = [t for t in tools.values() if t.cutter.name == cutter.name]
    tool = same[0] if same else Tool(0, cutter)  # 0: not from the table, no tool change
    return Operation("finish", tool, "steep" if args.steep else "zigzag")


def run_job(args):
    """A job folder or --operations: the named programs (and previews) for another
    cutter, material, scallop or dialect, from the height map alone."""
    from pathlib import Path

    from ..cam.cutters import parse_cutter
    from ..cam.operations import parse_operations
    from ..cam.sampling import check_heightmap
    from ..errors import InkSliceError
    from ..surface.base import stand_on_base

    src = Path(args.heightmap)
    csv = src / "heightmap.csv" if src.is_dir() else src
    if not csv.is_file():
        raise InkSliceError(src, "holds no heightmap.csv: process the scan first")
    out_dir = Path(args.out) if args.out else (src if src.is_dir() else None)
    if out_dir is None:
        raise InkSliceError("-o", "give the folder to write the programs into")
    if not out_dir.is_dir():
        raise InkSliceError(out_dir, "is not a folder (with a job folder or --operations, -o names a folder)")
    hm, fix = stand_on_base(read_heightmap_csv(csv))
    check_heightmap(hm, where=str(csv))
    for sentence in fix.sentences():
        print(f"note: {csv}: {sentence}")
    tools = _tool_table(args)
    if args.operations:
        ops = parse_operations(args.operations, tools)
    else:
        with flags({"cutter": "--cutter"}):
            cutter = parse_cutter(args.cutter, args.flute_length, args.flutes)
        ops = [_finish_op(args, cutter, tools)]
    return _post_named(args, hm, ops, out_dir, None, job=args.job or (src.name if src.is_dir() else src.stem))


def _post_named(args, hm, ops, out_dir, only_name, job="job"):
    from pathlib import Path

    from ..cam.operations import plan_operations, post_operations
    from ..cam.preview import preview_json

    planned, top = plan_operations(
        hm,
        ops,
        scallop=args.scallop,
        steep_deg=args.steep_angle,
        stock_top=args.stock_top,
        resolution=args.resolution,
    )
    posted = post_operations(
        planned,
        top,
        args.dialect,
        job=job,
        material=args.material,
        clearance=args.clearance,
        z_offset=args.z_offset,
        machine=_machine(args),
        hm=hm,
    )
    if only_name is not None and len(posted) > 1:
        from ..errors import SettingError

        raise SettingError("-o", f"{args.dialect} needs one file per tool: give a folder")
    for p in planned:
        for n in p.notes:
            print(f"note: {n}")
    for p in posted:
        path = Path(out_dir) / (only_name or p.name)
        _write(path, p.text)
        line = f"{path}: {p.text.count(chr(10))} lines"
        if p.programs:
            line += f", estimated run time {p.runtime_s / 60:.1f} min"
            if args.preview or only_name is None:
                atomicio.write_text(path.with_suffix(".preview.json"), preview_json(p.programs))
        print(line)
    return 0
