"""The table of docs/results/shield-at-test/run.sh: per road and initial-lane setting, the mean of
the three seeds' survival and achievement with a 95 % percentile bootstrap interval over seeds
(``merge-alongside``: merge's dqfd-bc-alongside networks; ``allroads-<road>``: the allroads networks on
that road; the other rows dqfd-bc-alongside-safe's).

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import json
import sys
from pathlib import Path

from laneshift.tools.studies.stats import bootstrap_ci

out = Path(sys.argv[1])
print("| road | random lane: survival / achievement | non-target lane: survival / achievement | actions replaced |")
print("|---|---|---|---|")
for road in ("straight", "merge", "curve", "roundabout", "merge-alongside",
             "allroads-straight", "allroads-merge", "allroads-curve", "allroads-roundabout"):
    cells, replaced = [], []
    for lane in ("random", "non-target"):
        runs = [json.loads((out / f"{road}-s{s}-{lane}.json").read_text()) for s in range(3)]
        parts = []
        for key in ("survival_rate", "achievement_rate"):
            values = [100 * r[key] for r in runs]
            lo, hi = bootstrap_ci(values)
            parts.append(f"{sum(values) / 3:.1f} [{lo:.1f}, {hi:.1f}]")
        cells.append(" / ".join(parts))
        replaced += [r["shielded_step_rate"] for r in runs]
    print(f"| {road} | {cells[0]} | {cells[1]} | {100 * min(replaced):.1f}-{100 * max(replaced):.1f} % |")
