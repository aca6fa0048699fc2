"""The job report in a person's words: each statistic's plain name, unit and what it means.

report.json keeps the statistics under the names the dissertation and our code use (`Ea`,
`Ep_printed`, `inkslice:fit`); the job page shows these names instead, with the explanation a tap
away, and keeps the code names only as a small reference.
"""

from __future__ import annotations

from ..process import LABELS, UNCERTAINTY_PNG, label

# key: (plain name, unit, what it means)
STATISTICS = {
    "Ea": (
        "Mean error",
        "mm",
        "The average height difference between the scan and the true part, over every "
        "cell both cover. Smaller is better.",
    ),
    "max_error": (
        "Largest error",
        "mm",
        "The worst single cell: the biggest height difference anywhere on the "
        "part. One bad spot shows here even when the mean is small.",
    ),
    "sigma": (
        "Spread of the error",
        "mm",
        "How much the error varies from cell to cell (its standard deviation). "
        "Small means the error is even over the part.",
    ),
    "matching": (
        "Matching",
        "%",
        "100 % minus the mean error as a share of the part's height, the "
        "dissertation's figure of merit. Closer to 100 % is better.",
    ),
    "Ep_table": (
        "Mean error as a share of the height",
        "%",
        "The mean error divided by the part's height (below), as a percentage.",
    ),
    "Ep_printed": (
        "Mean relative error (dissertation's formula)",
        "%",
        "Each cell's error divided by its own "
        "height, averaged, as the dissertation printed it; low cells weigh heavily.",
    ),
    "n": ("Cells compared", "cells", "How many height-map cells had both a scanned and a true height."),
    "normaliser": (
        "Part height used for the shares",
        "mm",
        "The height the percentages are taken of (the dissertation's figure for its samples).",
    ),
}
ORDER = ("Ea", "max_error", "sigma", "matching", "Ep_table", "Ep_printed", "n", "normaliser")


def readable(statistics: dict) -> list[dict]:
    """report.json's statistics -> [{"title", "key", "rows": [{"name", "value", "unit", "help", "key"}]}]."""
    statistics = statistics or {}
    flat = {k: v for k, v in statistics.items() if not isinstance(v, dict)}
    groups = []
    if flat:  # one set of figures, not one per method
        statistics = {**{k: v for k, v in statistics.items() if isinstance(v, dict)}, "": flat}
    for key, stats in statistics.items():
        if not isinstance(stats, dict):
            continue
        try:
            title = label(key) if key else "Statistics"
        except (KeyError, ValueError):
            title = key
        rows = []
        for k in sorted(stats, key=lambda k: ORDER.index(k) if k in ORDER else len(ORDER)):
            name, unit, text = STATISTICS.get(k, (k, "", ""))
            rows.append({"key": k, "name": name, "value": stats[k], "unit": unit, "help": text})
        groups.append({"key": key, "title": title, "rows": rows})
    return sorted(groups, key=lambda g: not g["key"].startswith("inkslice:"))  # ours first


def picture_caption(name: str) -> str:
    """What a job's picture shows, in words (its alt text and caption)."""
    if name == UNCERTAINTY_PNG:
        return (
            "How sure each cell of the height map is (1-sigma, mm, scale on the right); "
            "the numbered boxes are the low-confidence regions the report and the G-code list"
        )
    if name.startswith("error_") and name.endswith(".png"):
        method = name[len("error_") : -len(".png")]
        ours = method.startswith("inkslice_")
        method = method[len("inkslice_") :] if ours else method
        if method in LABELS:
            who = label(("inkslice:" if ours else "seed:") + method)
            return f"Where {who} differs from the true part (error in mm, scale on the right)"
    return name
