"""The report of one processing run (report.md): what was used, the base plane, the
uncertainty per cell and, with a ground truth, the statistics beside the dissertation's
printed tables."""

from __future__ import annotations

import numpy as np

from .pipelines import Job, label
from .surface.seedtables import TABLES


def report_markdown(job: Job) -> str:
    what = (
        "InkSlice (sub-pixel waterlines, regularised fit)"
        if job.pipeline == "inkslice"
        else "the seed method's (Canny edge pixels, 50 x 50 grid)"
    )
    lines = [
        f"# InkSlice report: {job.scan_folder.name}",
        "",
        f"Pipeline: {what}. Method written to heightmap.csv and the G-code: {label(job.key)}.",
        "",
    ]
    lines += [f"- {n}" for n in job.notes]
    if job.calibration:
        from .calibration_used import markdown

        lines += markdown(job.calibration) + [""]
    base = job.diagnostics.get(job.method, {}).get("base") if job.pipeline == "inkslice" else None
    if base is not None:
        lines += [
            "",
            "Base plane (the part stands on the base top, z = 0): "
            f"{base['clamped_cells']} cells clamped up to it (deepest dip {base['deepest_dip_mm']:.3f} mm), "
            f"{base['filled_cells']} gap cells filled from their neighbours, "
            f"{base['base_cells']} hole cells set to the base top.",
            "",
        ]
    lines += uncertainty_markdown(job)
    if not job.stats:
        lines.append("No ground truth for this scan: statistics need a rendered scan or a known part.")
        return "\n".join(lines) + "\n"
    lines += [
        f"Ground truth: `{job.truth}`. Heights in the dissertation's frame; "
        "Ep (table) = 100 Ea / max|Zf|, degree of matching = 100 - Ep (table).",
        "",
        "| method | max error mm | Ea mm | sigma mm | Ep table % | Ep printed % | matching % |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, s in job.stats.items():
        lines.append(
            f"| {label(k)} | {s['max_error']:.4f} | {s['Ea']:.4f} | {s['sigma']:.4f} "
            f"| {s['Ep_table']:.4f} | {s['Ep_printed']:.4f} | {s['matching']:.4f} |"
        )
    if job.truth in TABLES:
        lines += ["", f"The dissertation's table for {job.truth} (Ea / sigma / Ep):", ""]
        for k, (ea, sd, ep) in TABLES[job.truth].items():
            lines.append(f"- {k}: {ea:.4f} / {sd:.4g} / {ep:.4f}")
    lines += ["", "Error pictures: " + ", ".join(f"`{png_name(k)}`" for k in job.stats)]
    return "\n".join(lines) + "\n"


UNCERTAINTY_PNG = "uncertainty.png"


def uncertainty_summary(job: Job, threshold_mm=None) -> dict | None:
    """Where the written height map is sure and where not: sources, low-confidence regions."""
    from .surface.confidence import low_confidence_regions, source_summary
    from .surface.uncertainty import DEFAULT_UNCERTAIN_MM

    hm = job.heightmap
    if hm.sigma is None:
        return None
    t = DEFAULT_UNCERTAIN_MM if threshold_mm is None else threshold_mm
    on = hm.on_part & np.isfinite(hm.sigma)
    regions = low_confidence_regions(hm, t)
    return {
        "threshold_mm": t,
        "sources": source_summary(hm),
        "median_mm": float(np.median(hm.sigma[on])) if on.any() else None,
        "low_confidence_share": float(sum(r.share for r in regions)),
        "regions": [
            {
                "xmin": r.xmin,
                "xmax": r.xmax,
                "ymin": r.ymin,
                "ymax": r.ymax,
                "share": r.share,
                "worst_mm": r.worst_mm,
                "source": r.source,
                "edge": r.edge,
            }
            for r in regions
        ],
    }


def uncertainty_markdown(job: Job, most=8) -> list[str]:
    u = job.diagnostics.get("uncertainty") or uncertainty_summary(job)
    if u is None:
        return []
    src = ", ".join(f"{name} {100 * share:.1f} %" for name, share in u["sources"].items())
    out = [
        "",
        f"Uncertainty per cell (`{UNCERTAINTY_PNG}`, and the columns source, uncertainty_mm of "
        f"heightmap.csv): median {u['median_mm']:.3f} mm. How the cells were obtained: {src}.",
        "",
    ]
    if not u["regions"]:
        out += [f"Every cell is within {u['threshold_mm']:g} mm.", ""]
        return out
    inside = [r for r in u["regions"] if not r.get("edge")]
    at_edge = " and at its edge" if len(inside) < len(u["regions"]) else ""
    out += [
        f"Low confidence (uncertainty over {u['threshold_mm']:g} mm): {100 * u['low_confidence_share']:.1f} % "
        f"of the part in {len(inside)} region(s){at_edge}, largest first (the G-code header lists them too):",
        "",
        "| region | x mm | y mm | share % | up to mm | mostly |",
        "|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(inside[:most], start=1):
        out.append(
            f"| {i} | {r['xmin']:.1f} .. {r['xmax']:.1f} | {r['ymin']:.1f} .. {r['ymax']:.1f} "
            f"| {100 * r['share']:.1f} | {r['worst_mm']:.2f} | {r['source']} |"
        )
    if len(inside) > most:
        out.append(
            f"| ... | {len(inside) - most} smaller regions | | "
            f"{100 * sum(r['share'] for r in inside[most:]):.1f} | | |"
        )
    for r in u["regions"]:
        if r.get("edge"):  # the outermost cells all round: the outline is known to a cell there
            out.append(
                f"| edge | all round | | {100 * r['share']:.1f} | {r['worst_mm']:.2f} | "
                "the part's outline, known to a cell |"
            )
    return out + [""]


def png_name(key):
    """error_lsq3.png for the seed method (the dissertation's figures 5-1..5-16), error_inkslice_fit.png for ours."""
    pipeline, method = key.split(":")
    return f"error_{method}.png" if pipeline == "seed" else f"error_{pipeline}_{method}.png"
