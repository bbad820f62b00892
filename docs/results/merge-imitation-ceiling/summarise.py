"""How well merge's networks can copy the scripted driver (``run.sh``): the three pre-trained networks of seed 1
beside the driver and the published merge networks on the same 800 validation episodes per initial-lane setting
(merge-val800's ``episodes.csv``), each network's achievement against the driver's with a 95 % interval from a
bootstrap over the episodes (paired: the driver and the network on the same resampled episodes; one run each, so
the seed-to-seed spread, about 1.8 points on merge, is not in it), and achievement by start lane. Writes
``episodes.csv`` beside the table so that the table can be made again without the evaluations.

    python docs/results/merge-imitation-ceiling/summarise.py EVAL_DIR > docs/results/merge-imitation-ceiling/table.md

EVAL_DIR holds ``ceil<X>-s1-<lane>.jsonl`` (``laneshift eval --episodes-out``), or ``episodes.csv`` from an earlier
call.

Room: a study's script (docs/results). May import: numpy and laneshift's study tools.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from laneshift.tools.studies.outcome_files import (LANES, achievement_by_start_lane, outcome_rows, read_outcomes,
                                                    write_outcomes_csv)
from laneshift.tools.studies.stats import RESAMPLES, paired_difference_ci

HERE = Path(__file__).parent
NETWORKS = {"ceilA-s1": "A: the recipe's pre-training (TD + margin + cross-entropy, 390 driver episodes)",
            "ceilB-s1": "B: the imitation losses alone, the same 390 episodes",
            "ceilC-s1": "C: the imitation losses alone, 2,000 driver episodes"}
PUBLISHED = {"merge-pre60k-hold": "the published final networks with the holding (3 seeds pooled)",
             "merge-pre60k": "the published final networks without it (3 seeds pooled)"}



def main(out: Path) -> None:
    ours = read_outcomes(out)
    if any(out.glob("*.jsonl")):
        write_outcomes_csv(ours, HERE / "episodes.csv")
    theirs = read_outcomes(HERE.parent / "merge-val800")
    runs = {**theirs, **ours}
    order = sorted(runs[("driver", "non-target")])
    n = len(order)
    groups = {name: [name] for name in NETWORKS if (name, "non-target") in runs}
    groups |= {recipe: [f"{recipe}-s{s}" for s in range(3)] for recipe in PUBLISHED}
    labels = {**NETWORKS, **PUBLISHED}
    print(f"**Merge behind the shield, seed 1's networks at the end of pre-training, on {n} validation episodes per "
          f"initial lane** (episode seeds {order[0]:,}-{order[-1]:,}, 300 steps, merge-val800's episodes; `run.sh`, "
          "`summarise.py`). Survival / achievement, %; achievement minus the driver's with a 95 % interval "
          f"(episodes resampled, paired, {RESAMPLES:,} times).\n")
    print("| network | non-target lane | against the driver | random lane | against the driver |")
    print("|---|---|---|---|---|")
    driver = {lane: np.array(outcome_rows(runs, ["driver"], lane, order, "achieved")) for lane in LANES}
    for name, members in groups.items():
        cells = []
        for lane in LANES:
            surv = np.array(outcome_rows(runs, members, lane, order, "survived"))
            ach = np.array(outcome_rows(runs, members, lane, order, "achieved"))
            lo, hi = paired_difference_ci(ach, driver[lane])
            cells += [f"{100 * surv.mean():.1f} / **{100 * ach.mean():.1f}**",
                      f"{100 * (ach.mean() - driver[lane].mean()):+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]"]
        print(f"| {labels[name]} | " + " | ".join(cells) + " |")
    cells = []
    for lane in LANES:
        surv = np.array(outcome_rows(runs, ["driver"], lane, order, "survived"))
        cells += [f"{100 * surv.mean():.1f} / {100 * driver[lane].mean():.1f}", ""]
    print("| the scripted driver behind the shield | " + " | ".join(cells) + " |")
    starts = sorted({o.start_lane for o in runs[("driver", "non-target")].values()})
    print("\nAchievement by the lane an episode starts in (non-target setting; lane 0 is the fast lane, lane 2 the "
          "on-ramp):\n")
    print("| network | " + " | ".join(f"start lane {k}" for k in starts) + " |")
    print("|---|" + "---|" * len(starts))
    for name, members in [*groups.items(), ("driver", ["driver"])]:
        by_start = achievement_by_start_lane(runs, members)
        print(f"| {labels.get(name, 'the scripted driver')} | "
              + " | ".join(f"{100 * by_start[k][0]:.1f} ({by_start[k][1]} episodes)" for k in starts) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
