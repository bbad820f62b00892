"""The merge networks with and without the holding, and the scripted driver, on 800 fresh validation episodes per
initial-lane setting (``run.sh``): each run's survival and achievement, each recipe's mean over its seeds, and the
holding's lift with a 95 % interval from a bootstrap that resamples the episodes (paired: both recipes on the same
resampled episodes) and the seeds (each recipe's three); achievement by start lane. Also writes ``episodes.csv``
beside the table (one row per run and lane: the few per-episode fields the table reads, as strings) so that the table
can be made again without the evaluations.

    python docs/results/merge-val800/summarise.py OUT_DIR > docs/results/merge-val800/table.md

OUT_DIR holds ``<run>-<lane>.jsonl`` (``laneshift eval --episodes-out``), or ``episodes.csv`` from an earlier call.

Room: a study's script (docs/results). May import: the standard library and numpy.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

LANES = ("non-target", "random")
RECIPES = {"merge-pre60k-hold": "with the holding (`actor.hold_mu=2`; published)",
           "merge-pre60k": "without it (published before)"}
RESAMPLES = 10_000


def read_runs(out: Path) -> dict[tuple[str, str], dict[int, tuple[bool, bool, int]]]:
    """{(run, lane): {episode seed: (survived, achieved, start lane)}} from the jsonl files or episodes.csv."""
    runs: dict[tuple[str, str], dict[int, tuple[bool, bool, int]]] = {}
    files = sorted(out.glob("*.jsonl"))
    if files:
        for f in files:
            name = f.name[:-len(".jsonl")]
            lane = next(lane for lane in LANES if name.endswith("-" + lane))
            eps = [json.loads(line) for line in f.read_text().splitlines() if line.strip()]
            runs[(name[:-len(lane) - 1], lane)] = {o["seed"]: (bool(o["survived"]), bool(o["achieved"]),
                                                               int(o["start_lane"])) for o in eps}
        return runs
    with (out / "episodes.csv").open() as fh:
        for row in csv.DictReader(fh):
            first = int(row["first_episode_seed"])
            runs[(row["run"], row["lane"])] = {
                first + i: (s == "1", a == "1", int(k))
                for i, (s, a, k) in enumerate(zip(row["survived"], row["achieved"], row["start_lane"]))}
    return runs


def write_csv(runs: dict, path: Path) -> None:
    """One row per run and lane: episode i (seed first + i) is character i of each 0/1 (or lane) string."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "lane", "first_episode_seed", "survived", "achieved", "start_lane"])
        for (run, lane), eps in sorted(runs.items()):
            seeds = sorted(eps)
            assert seeds == list(range(seeds[0], seeds[0] + len(seeds))), "episode seeds not consecutive"
            w.writerow([run, lane, seeds[0], "".join(str(int(eps[e][0])) for e in seeds),
                        "".join(str(int(eps[e][1])) for e in seeds), "".join(str(eps[e][2]) for e in seeds)])


def lift_interval(hold: np.ndarray, base: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """95 % interval of mean(hold seeds) - mean(base seeds) in points: episodes resampled (the same ones for
    both recipes) and each recipe's seeds resampled. hold, base: [seeds, episodes] of 0/1."""
    n = hold.shape[1]
    diffs = np.empty(RESAMPLES)
    for i in range(RESAMPLES):
        eps = rng.integers(0, n, n)
        h = hold[rng.integers(0, len(hold), len(hold))][:, eps].mean()
        b = base[rng.integers(0, len(base), len(base))][:, eps].mean()
        diffs[i] = 100 * (h - b)
    lo, hi = np.percentile(diffs, [2.5, 97.5])
    return float(lo), float(hi)


def main(out: Path) -> None:
    runs = read_runs(out)
    if any(out.glob("*.jsonl")):
        write_csv(runs, Path(__file__).with_name("episodes.csv"))
    rng = np.random.default_rng(0)
    n = len(next(iter(runs.values())))
    print(f"**Merge behind the shield on {n} fresh validation episodes per initial lane** (episode seeds "
          f"200,200-{200_200 + n - 1:,}, 300 steps; never used for a choice; `run.sh`, `summarise.py`). "
          "Survival / achievement, %; a recipe's row is the mean of its seeds' rates.\n")
    print("| run | non-target lane | random lane |")
    print("|---|---|---|")

    def rates(run: str, lane: str) -> tuple[float, float]:
        eps = runs[(run, lane)].values()
        return 100 * np.mean([s for s, _, _ in eps]), 100 * np.mean([a for _, a, _ in eps])

    names = sorted({run for run, _ in runs})
    for recipe, label in RECIPES.items():
        seeds = [r for r in names if r.rsplit("-s", 1)[0] == recipe]
        cells = []
        for lane in LANES:
            s = np.mean([rates(r, lane)[0] for r in seeds])
            a = np.mean([rates(r, lane)[1] for r in seeds])
            per = ", ".join(f"{rates(r, lane)[1]:.1f}" for r in seeds)
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
            seeds = [r for r in names if r.rsplit("-s", 1)[0] == recipe]
            order = sorted(runs[(seeds[0], lane)])
            arrays[recipe] = np.array([[runs[(r, lane)][e][1] for e in order] for r in seeds], dtype=float)
        hold, base = arrays["merge-pre60k-hold"], arrays["merge-pre60k"]
        lo, hi = lift_interval(hold, base, rng)
        print(f"- {lane} lane: the holding's lift in achievement {100 * (hold.mean() - base.mean()):+.1f} points "
              f"[{lo:+.1f}, {hi:+.1f}] (95 %, episodes and seeds resampled, {RESAMPLES:,} times)")
    print("\nAchievement by the lane an episode starts in (non-target setting; lane 0 is the fast lane; a recipe's "
          "seeds pooled):\n")
    starts = sorted({k for (_, lane), eps in runs.items() if lane == "non-target" for _, _, k in eps.values()})
    print("| run | " + " | ".join(f"start lane {k}" for k in starts) + " |")
    print("|---|" + "---|" * len(starts))
    for label, members in [(recipe, [r for r in names if r.rsplit("-s", 1)[0] == recipe]) for recipe in RECIPES] + \
            [(run, [run]) for run in others]:
        cells = []
        for k in starts:
            hits = [a for r in members for _, a, lane in runs[(r, "non-target")].values() if lane == k]
            cells.append(f"{100 * np.mean(hits):.1f} ({len(hits) // len(members)} episodes)")
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
