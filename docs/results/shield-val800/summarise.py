"""The published networks behind the shield (the imitation losses fading to 0) and the scripted driver behind the same
shield on 800 fresh validation episodes per initial-lane setting (``run.sh``): per road, the seeds' mean survival and
achievement, each seed's achievement, the driver's, and the networks' lead over the driver in achievement with a 95 %
interval from a bootstrap that resamples the episodes (the networks and the driver on the same resampled episodes)
and the seeds. Also writes ``episodes.csv`` beside the table (``laneshift.tools.studies.outcome_files``) so that
the table can be made again without the evaluations.

    python docs/results/shield-val800/summarise.py OUT_DIR > docs/results/shield-val800/table.md

OUT_DIR holds ``<road>-s<N>-<lane>.jsonl`` and ``<road>-driver-<lane>.jsonl`` (``laneshift eval --episodes-out``), or
``episodes.csv`` from an earlier call.

Room: a study's script (docs/results). May import: numpy and laneshift's study tools.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from laneshift.tools.studies.outcome_files import LANES, read_outcomes, write_outcomes_csv
from laneshift.tools.studies.stats import RESAMPLES, paired_difference_ci


def main(out: Path) -> None:
    runs = read_outcomes(out)
    if any(out.glob("*.jsonl")):
        write_outcomes_csv(runs, Path(__file__).with_name("episodes.csv"))
    roads = sorted({run.rsplit("-", 1)[0] for run, _ in runs}, key=lambda r: ("policytraffic" in r, r))
    print("**Behind the shield on 800 fresh validation episodes per initial lane** (episode seeds 200,200-200,999, "
          "300 steps; never used for a choice; `run.sh`, `summarise.py`): the published networks whose imitation "
          "losses fade to 0 (3 seeds) against the scripted driver behind the same shield. Survival / achievement, %; "
          "the networks' row is the mean of their seeds' rates; the lead is the networks' achievement minus the "
          f"driver's, with a 95 % interval (episodes and seeds resampled, {RESAMPLES:,} times).\n")
    print("| road | initial lane | networks | achievement per seed | driver | lead in achievement |")
    print("|---|---|---|---|---|---|")
    for road in roads:
        for lane in LANES:
            seeds = sorted(r for r, ln in runs if ln == lane and r.startswith(road + "-s"))
            if not seeds or (road + "-driver", lane) not in runs:
                continue
            driver = runs[(road + "-driver", lane)]
            order = sorted(driver)
            if any(sorted(runs[(r, lane)]) != order for r in seeds):
                raise SystemExit(f"{road} {lane}: the networks and the driver drove different episodes")
            nets = np.array([[(runs[(r, lane)][e].survived, runs[(r, lane)][e].achieved) for e in order]
                             for r in seeds], dtype=float)  # [seed, episode, (survived, achieved)]
            drv = np.array([(driver[e].survived, driver[e].achieved) for e in order], dtype=float)
            lo, hi = (100 * x for x in paired_difference_ci(nets[:, :, 1], drv[None, :, 1]))
            per = ", ".join(f"{100 * a:.1f}" for a in nets[:, :, 1].mean(axis=1))
            lead = 100 * (nets[:, :, 1].mean() - drv[:, 1].mean())
            print(f"| {road} | {lane} | {100 * nets[:, :, 0].mean():.1f} / **{100 * nets[:, :, 1].mean():.1f}** "
                  f"| {per} | {100 * drv[:, 0].mean():.1f} / {100 * drv[:, 1].mean():.1f} "
                  f"| {lead:+.1f} [{lo:+.1f}, {hi:+.1f}] |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
