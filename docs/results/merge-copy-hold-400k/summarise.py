"""The copy-then-hold probe (``run.sh``) beside the published holding recipe's networks of the same seeds and the
scripted driver on 1,000 fresh validation episodes per initial-lane setting: survival / achievement per seed and
pooled, achievement by start lane, the probe's achievement minus each of theirs with a 95 % interval (episodes
resampled, paired; with several seeds, the seeds resampled too), and the rule written in ``run.sh`` before the probe
ran (on seed 1). Writes ``episodes.csv`` beside the table.

    python docs/results/merge-copy-hold-400k/summarise.py EVAL_DIR > docs/results/merge-copy-hold-400k/table.md

EVAL_DIR holds ``<run>-<lane>.jsonl`` (``laneshift eval --episodes-out``; runs ``driver``, ``D-s<N>`` and
``merge-pre60k-hold-s<N>``), or ``episodes.csv`` from an earlier call.

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
PROBE, HOLD = "D", "merge-pre60k-hold"
LABELS = {PROBE: "D: copy then hold", HOLD: "the holding recipe, published", "driver": "the scripted driver"}



def main(out: Path) -> None:
    runs = read_outcomes(out)
    if any(out.glob("*.jsonl")):
        write_outcomes_csv(runs, HERE / "episodes.csv")
    order = sorted(runs[("driver", "non-target")])
    # The seeds whose probe network and holding network have both driven both settings.
    seeds = sorted(int(r.rsplit("-s", 1)[1]) for r, lane in runs if r.startswith(PROBE + "-s") and lane == "random"
                   and (f"{HOLD}-s{r.rsplit('-s', 1)[1]}", "random") in runs
                   and (r, "non-target") in runs and (f"{HOLD}-s{r.rsplit('-s', 1)[1]}", "non-target") in runs)
    print(f"**Merge behind the shield, {len(order):,} fresh validation episodes per initial lane** (episode seeds "
          f"{order[0]:,}-{order[-1]:,}, 300 steps; `run.sh`, `summarise.py`). Survival / achievement, %; lanes 0 (the "
          "fast lane) and 2 (the on-ramp): achievement from the non-target setting by start lane.\n")
    starts = sorted({o.start_lane for o in runs[("driver", "non-target")].values()})
    print("| network | non-target lane | random lane | " + " | ".join(f"from lane {k}" for k in starts) + " |")
    print("|---|---|---|" + "---|" * len(starts))
    groups = [(f"{LABELS[name]}, seed {s}", [f"{name}-s{s}"]) for s in seeds for name in (PROBE, HOLD)]
    if len(seeds) > 1:
        groups += [(f"{LABELS[name]}, seeds {', '.join(map(str, seeds))} pooled", [f"{name}-s{s}" for s in seeds])
                   for name in (PROBE, HOLD)]
    groups.append((LABELS["driver"] + " behind the shield", ["driver"]))
    for label, names in groups:
        cells = [f"{100 * np.array(outcome_rows(runs, names, lane, order, 'survived')).mean():.1f} / "
                 f"{100 * np.array(outcome_rows(runs, names, lane, order)).mean():.1f}" for lane in LANES]
        by_start = achievement_by_start_lane(runs, names)
        cells += [f"{100 * by_start[k][0]:.1f} ({by_start[k][1]})" for k in starts]
        print(f"| {label} | " + " | ".join(cells) + " |")
    print()
    probe_names = [f"{PROBE}-s{s}" for s in seeds]
    for lane in LANES:
        probe = np.array(outcome_rows(runs, probe_names, lane, order))
        for label, names in ((LABELS[HOLD], [f"{HOLD}-s{s}" for s in seeds]), (LABELS["driver"], ["driver"])):
            base = np.array(outcome_rows(runs, names, lane, order))
            lo, hi = paired_difference_ci(probe, base)
            resampled = "episodes and seeds" if len(seeds) > 1 else "episodes"
            print(f"- {lane} lane, seeds {', '.join(map(str, seeds))}: D minus {label}: "
                  f"{100 * (probe.mean() - base.mean()):+.1f} points [{100 * lo:+.1f}, {100 * hi:+.1f}] (95 %, "
                  f"{resampled} resampled, paired, {RESAMPLES:,} times)")
    if 1 in seeds:
        lift = {lane: 100 * (np.array(outcome_rows(runs, [f"{PROBE}-s1"], lane, order)).mean()
                             - np.array(outcome_rows(runs, [f"{HOLD}-s1"], lane, order)).mean()) for lane in LANES}
        taken = lift["non-target"] >= 1.0 and lift["random"] >= -1.0
        print(f"\nThe rule on seed 1 (run.sh: achievement over the holding's seed 1 at least +1.0 from a non-target "
              f"lane and at least -1.0 from a random lane): {lift['non-target']:+.1f} and {lift['random']:+.1f}, "
              f"{'worth the other two seeds' if taken else 'stopped'}.")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
