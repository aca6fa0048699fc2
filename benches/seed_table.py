"""Re-run the dissertation's experiment on the virtual bench and print it beside tables 5-1..5-4.

For samples 1-4 and level steps of 1 and 2 mm: render a scan (2048 x 1536),
process it with every surface method, and print Ea / sigma / Ep (table form) /
degree of matching per method beside the dissertation's numbers.

    .venv/bin/python benches/seed_table.py            # full run
    .venv/bin/python benches/seed_table.py --quick    # 1 mm steps only
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from appliance import process as proc                      # noqa: E402
from appliance.sim import surfaces                          # noqa: E402
from appliance.surface.seed import LABELS, METHODS         # noqa: E402
from appliance.surface.seedtables import TABLES            # noqa: E402

TABLE_KEY = {"captured": "captured", "spline": "spline", "nearest": "nearest", "lsq3": "lsq"}


def render(sample, folder, step, effects):
    from appliance.sim.levels import sculpture_levels
    from appliance.sim.scanrender import render_scan
    surface = surfaces.get(sample)
    render_scan(surface, folder, levels=sculpture_levels(surface, step), effects=effects, seed=1)


def row(label, s, ref=None):
    out = f"  {label:<26} {s['Ea']:8.4f} {s['sigma']:8.4f} {s['Ep_table']:8.4f} {s['matching']:9.4f}"
    if ref:
        out += f"   | {ref[0]:8.4f} {ref[1]:9.4g} {ref[2]:8.4f}"
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--effects", default="realistic", choices=("clean", "realistic"))
    ap.add_argument("--samples", default="sample1,sample2,sample3,sample4")
    args = ap.parse_args()
    steps = (1.0,) if args.quick else (1.0, 2.0)
    effects = args.effects
    with tempfile.TemporaryDirectory(prefix="seed-table-") as tmp:
        for sample in args.samples.split(","):
            for step in steps:
                folder = Path(tmp) / f"{sample}-{step:g}"
                t0 = time.perf_counter()
                render(sample, folder, step, effects)
                t1 = time.perf_counter()
                job = proc.process(folder, method="lsq3")
                t2 = time.perf_counter()
                print(f"\n{sample}, level step {step:g} mm, effects {args.effects} "
                      f"(render {t1 - t0:.1f} s, process {t2 - t1:.1f} s)")
                print(f"  {'method':<26} {'Ea mm':>8} {'sigma':>8} {'Ep tab%':>8} {'match %':>9}"
                      f"   | {'diss Ea':>8} {'diss sigma':>9} {'diss Ep':>8}")
                for m in METHODS:
                    ref = TABLES[sample].get(TABLE_KEY.get(m, ""))
                    print(row(LABELS[m], job.stats[m], ref))


if __name__ == "__main__":
    main()
