"""The tables of docs/results/shield-figures/run.sh and run_more.sh: per network set and shield figures, the mean of
the three seeds' survival and achievement (validation: the plain means; test: with a 95 % percentile
bootstrap interval over seeds), and on the test episodes the drivers behind the same shield.

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import json
import sys
from pathlib import Path

from laneshift.tools.studies.stats import bootstrap_ci

out = Path(sys.argv[1])
NETS = {"merge": "merge-dqfd-bc-alongside-gaps-safe-shield", "straight": "straight-dqfd-bc-alongside-safe-shield",
        "curve": "curve-dqfd-bc-alongside-safe-shield", "roundabout": "roundabout-dqfd-bc-alongside-safe-shield",
        "straight-policytraffic": "straight-policytraffic-dqfd-bc-alongside-safe-shield"}
LANES = ("random", "non-target")


def cell(runs: list[dict], interval: bool) -> str:
    parts = []
    for key in ("survival_rate", "achievement_rate"):
        values = [100 * r[key] for r in runs]
        text = f"{sum(values) / len(values):.1f}"
        if interval:
            lo, hi = bootstrap_ci(values)
            text += f" [{lo:.1f}, {hi:.1f}]"
        parts.append(text)
    return " / ".join(parts)


for split, interval in (("validation", False), ("test", True)):
    print(f"\n{split}:\n")
    print("| road | shield figures | random lane: survival / achievement | non-target lane: survival / achievement | actions replaced |")
    print("|---|---|---|---|---|")
    for road, net in NETS.items():
        for gap, decel in (("3.0", "0.9"), ("2.0", "1.0"), ("2.0", "0.9")):
            files = {lane: [out / split / f"{net}-seed{s}-gap{gap}-decel{decel}-{lane}.json" for s in range(3)]
                     for lane in LANES}
            if not all(f.is_file() for fs in files.values() for f in fs):
                continue
            runs = {lane: [json.loads(f.read_text()) for f in fs] for lane, fs in files.items()}
            rates = [r["shielded_step_rate"] for lane in LANES for r in runs[lane]]
            print(f"| {road} | {gap} m, {decel} m/s² | {cell(runs['random'], interval)} | "
                  f"{cell(runs['non-target'], interval)} | {100 * min(rates):.1f}-{100 * max(rates):.1f} % |")
        base = out / split / f"baselines-{road}-gap2.0-decel1.0.json"
        if base.is_file():
            for name, by_lane in json.loads(base.read_text())["drivers"].items():
                print(f"| {road} | {name} behind the shield at 2.0 m, 1.0 m/s² | {cell([by_lane['random']], False)} | "
                      f"{cell([by_lane['non-target']], False)} | |")
