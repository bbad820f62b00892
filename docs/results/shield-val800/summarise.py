"""The published networks behind the shield (the imitation losses fading to 0) and the scripted driver behind the same
shield on 800 fresh validation episodes per initial-lane setting (``run.sh``): per road, the seeds' mean survival and
achievement, each seed's achievement, the driver's, and the networks' lead over the driver in achievement with a 95 %
interval from a bootstrap that resamples the episodes (the networks and the driver on the same resampled episodes)
and the seeds. Also writes ``episodes.csv`` beside the table (one row per run and lane, each episode's outcome as one
character of a string) so that the table can be made again without the evaluations.

    python docs/results/shield-val800/summarise.py OUT_DIR > docs/results/shield-val800/table.md

OUT_DIR holds ``<road>-s<N>-<lane>.jsonl`` and ``<road>-driver-<lane>.jsonl`` (``laneshift eval --episodes-out``), or
``episodes.csv`` from an earlier call.

Room: a study's script (docs/results). May import: the standard library and numpy.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

LANES = ("non-target", "random")
RESAMPLES = 10_000


def read_runs(out: Path) -> dict[tuple[str, str], dict[int, tuple[bool, bool]]]:
    """{(run, lane): {episode seed: (survived, achieved)}} from the jsonl files, else from episodes.csv."""
    runs: dict[tuple[str, str], dict[int, tuple[bool, bool]]] = {}
    files = sorted(out.glob("*.jsonl"))
    if files:
        for f in files:
            name = f.name[:-len(".jsonl")]
            lane = next(lane for lane in LANES if name.endswith("-" + lane))
            eps = [json.loads(line) for line in f.read_text().splitlines() if line.strip()]
            runs[(name[:-len(lane) - 1], lane)] = {o["seed"]: (bool(o["survived"]), bool(o["achieved"])) for o in eps}
        return runs
    with (out / "episodes.csv").open() as fh:
        for row in csv.DictReader(fh):
            first = int(row["first_episode_seed"])
            runs[(row["run"], row["lane"])] = {first + i: (s == "1", a == "1")
                                               for i, (s, a) in enumerate(zip(row["survived"], row["achieved"]))}
    return runs


def write_csv(runs: dict, path: Path) -> None:
    """One row per run and lane: episode i (seed first + i) is character i of each 0/1 string."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "lane", "first_episode_seed", "survived", "achieved"])
        for (run, lane), eps in sorted(runs.items()):
            seeds = sorted(eps)
            assert seeds == list(range(seeds[0], seeds[0] + len(seeds))), "episode seeds not consecutive"
            w.writerow([run, lane, seeds[0], "".join(str(int(eps[e][0])) for e in seeds),
                        "".join(str(int(eps[e][1])) for e in seeds)])


def lead_interval(nets: np.ndarray, driver: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """95 % interval of mean(network seeds) - driver in points: episodes resampled (the same for both), seeds
    resampled. nets: [seeds, episodes] of 0/1; driver: [episodes]."""
    n = driver.shape[0]
    leads = np.empty(RESAMPLES)
    for i in range(RESAMPLES):
        eps = rng.integers(0, n, n)
        leads[i] = 100 * (nets[rng.integers(0, len(nets), len(nets))][:, eps].mean() - driver[eps].mean())
    lo, hi = np.percentile(leads, [2.5, 97.5])
    return float(lo), float(hi)


def main(out: Path) -> None:
    runs = read_runs(out)
    if any(out.glob("*.jsonl")):
        write_csv(runs, Path(__file__).with_name("episodes.csv"))
    rng = np.random.default_rng(0)
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
            order = sorted(runs[(road + "-driver", lane)])
            if any(sorted(runs[(r, lane)]) != order for r in seeds):
                raise SystemExit(f"{road} {lane}: the networks and the driver drove different episodes")
            nets = np.array([[runs[(r, lane)][e] for e in order] for r in seeds], dtype=float)  # [seed, ep, 2]
            drv = np.array([runs[(road + "-driver", lane)][e] for e in order], dtype=float)
            lo, hi = lead_interval(nets[:, :, 1], drv[:, 1], rng)
            per = ", ".join(f"{100 * a:.1f}" for a in nets[:, :, 1].mean(axis=1))
            lead = 100 * (nets[:, :, 1].mean() - drv[:, 1].mean())
            print(f"| {road} | {lane} | {100 * nets[:, :, 0].mean():.1f} / **{100 * nets[:, :, 1].mean():.1f}** "
                  f"| {per} | {100 * drv[:, 0].mean():.1f} / {100 * drv[:, 1].mean():.1f} "
                  f"| {lead:+.1f} [{lo:+.1f}, {hi:+.1f}] |")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
