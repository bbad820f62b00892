"""The merge networks with and without the holding, and the scripted driver, on 800 fresh validation episodes per
initial-lane setting (``run.sh``): each run's survival and achievement, each recipe's mean over its seeds, and the
holding's lift with a 95 % interval from a bootstrap that resamples the episodes (paired: both recipes on the same
resampled episodes) and the seeds (each recipe's three); achievement by start lane. Also writes ``episodes.csv``
beside the table (``laneshift.tools.studies.outcome_files``) so that the table can be made again without the
evaluations.

    python docs/results/merge-val800/summarise.py OUT_DIR > docs/results/merge-val800/table.md

OUT_DIR holds ``<run>-<lane>.jsonl`` (``laneshift eval --episodes-out``), or ``episodes.csv`` from an earlier call.

Room: a study's script (docs/results). May import: numpy and laneshift's study tools.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from laneshift.tools.studies.outcome_files import (LANES, achievement_by_start_lane, outcome_rows, read_outcomes,
                                                    write_outcomes_csv)
from laneshift.tools.studies.stats import RESAMPLES, paired_difference_ci

RECIPES = {"merge-pre60k-hold": "with the holding (`actor.hold_mu=2`; published)",
           "merge-pre60k": "without it (published before)"}


def main(out: Path) -> None:
    runs = read_outcomes(out)
    if any(out.glob("*.jsonl")):
        write_outcomes_csv(runs, Path(__file__).with_name("episodes.csv"))
    n = len(next(iter(runs.values())))
    print(f"**Merge behind the shield on {n} fresh validation episodes per initial lane** (episode seeds "
          f"200,200-{200_200 + n - 1:,}, 300 steps; never used for a choice; `run.sh`, `summarise.py`). "
          "Survival / achievement, %; a recipe's row is the mean of its seeds' rates.\n")
    print("| run | non-target lane | random lane |")
    print("|---|---|---|")

    def rates(run: str, lane: str) -> tuple[float, float]:
        eps = runs[(run, lane)].values()
        return 100 * np.mean([o.survived for o in eps]), 100 * np.mean([o.achieved for o in eps])

    names = sorted({run for run, _ in runs})
    members = {recipe: [r for r in names if r.rsplit("-s", 1)[0] == recipe] for recipe in RECIPES}
    for recipe, label in RECIPES.items():
        cells = []
        for lane in LANES:
            s = np.mean([rates(r, lane)[0] for r in members[recipe]])
            a = np.mean([rates(r, lane)[1] for r in members[recipe]])
            per = ", ".join(f"{rates(r, lane)[1]:.1f}" for r in members[recipe])
            cells.append(f"{s:.1f} / **{a:.1f}** (achievement per seed {per})")
        print(f"| {recipe}, {label} | {cells[0]} | {cells[1]} |")
    others = sorted((r for r in names if r.rsplit("-s", 1)[0] not in RECIPES), key=lambda r: r != "driver")
    for run in others:
        cells = [f"{rates(run, lane)[0]:.1f} / {rates(run, lane)[1]:.1f}" for lane in LANES]
        label = "the scripted driver behind the shield" if run == "driver" else f"{run} (a stopped probe's network)"
        print(f"| {label} | {cells[0]} | {cells[1]} |")
    print()
    for lane in LANES:
        arrays = {}
        for recipe in RECIPES:
            order = sorted(runs[(members[recipe][0], lane)])
            arrays[recipe] = np.array(outcome_rows(runs, members[recipe], lane, order))
        hold, base = arrays["merge-pre60k-hold"], arrays["merge-pre60k"]
        lo, hi = paired_difference_ci(hold, base)
        print(f"- {lane} lane: the holding's lift in achievement {100 * (hold.mean() - base.mean()):+.1f} points "
              f"[{100 * lo:+.1f}, {100 * hi:+.1f}] (95 %, episodes and seeds resampled, {RESAMPLES:,} times)")
    print("\nAchievement by the lane an episode starts in (non-target setting; lane 0 is the fast lane; a recipe's "
          "seeds pooled):\n")
    starts = sorted({o.start_lane for (_, lane), eps in runs.items() if lane == "non-target" for o in eps.values()})
    print("| run | " + " | ".join(f"start lane {k}" for k in starts) + " |")
    print("|---|" + "---|" * len(starts))
    for label, group in list(members.items()) + [(run, [run]) for run in others]:
        by_start = achievement_by_start_lane(runs, group)
        print(f"| {label} | " + " | ".join(f"{100 * by_start[k][0]:.1f} ({by_start[k][1]} episodes)" for k in starts)
              + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
