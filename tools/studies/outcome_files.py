"""Per-episode outcomes of several evaluations on the same episodes, read and kept small: the files that
``laneshift eval --episodes-out`` writes (one JSON line per episode), named ``<run>-<lane>.jsonl``, and one compact
CSV that holds what a study's table reads from them (one row per run and lane; episode i, seed ``first + i``, is
character i of each outcome string), so that a study commits kilobytes and its table can be made again without the
evaluations. The studies of docs/results (merge-val800, shield-val800) compare runs episode by episode with
:func:`laneshift.tools.studies.stats.paired_difference_ci`.

Room: the tools (studies). May import: the standard library only.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

#: The initial-lane settings a file name may end with.
LANES = ("non-target", "random")


@dataclass(frozen=True)
class Outcome:
    survived: bool
    achieved: bool
    start_lane: int


#: {(run, lane): {episode seed: outcome}}
Outcomes = dict[tuple[str, str], dict[int, Outcome]]


def read_outcomes(folder: Path, csv_name: str = "episodes.csv") -> Outcomes:
    """The ``<run>-<lane>.jsonl`` files of ``folder``; without any, its ``csv_name`` (:func:`write_outcomes_csv`)."""
    runs: Outcomes = {}
    files = sorted(folder.glob("*.jsonl"))
    for f in files:
        name = f.name[:-len(".jsonl")]
        lane = next((lane for lane in LANES if name.endswith("-" + lane)), None)
        if lane is None:
            raise ValueError(f"{f}: the name does not end with an initial lane ({', '.join(LANES)})")
        eps = [json.loads(line) for line in f.read_text().splitlines() if line.strip()]
        runs[(name[:-len(lane) - 1], lane)] = {
            int(o["seed"]): Outcome(bool(o["survived"]), bool(o["achieved"]), int(o["start_lane"])) for o in eps}
    if files:
        return runs
    with (folder / csv_name).open() as fh:
        for row in csv.DictReader(fh):
            first = int(row["first_episode_seed"])
            runs[(row["run"], row["lane"])] = {
                first + i: Outcome(s == "1", a == "1", int(k))
                for i, (s, a, k) in enumerate(zip(row["survived"], row["achieved"], row["start_lane"], strict=True))}
    return runs


def write_outcomes_csv(runs: Outcomes, path: Path) -> None:
    """One row per run and lane; the episode seeds of each must be consecutive (one ``--seed``, ``--episodes``)."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["run", "lane", "first_episode_seed", "survived", "achieved", "start_lane"])
        for (run, lane), eps in sorted(runs.items()):
            seeds = sorted(eps)
            if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
                raise ValueError(f"{run} {lane}: the episode seeds are not consecutive")
            if any(not 0 <= eps[e].start_lane <= 9 for e in seeds):
                raise ValueError(f"{run} {lane}: a start lane outside 0-9 does not fit one character")
            w.writerow([run, lane, seeds[0], "".join(str(int(eps[e].survived)) for e in seeds),
                        "".join(str(int(eps[e].achieved)) for e in seeds),
                        "".join(str(eps[e].start_lane) for e in seeds)])


def outcome_rows(runs: Outcomes, names: list[str], lane: str, order: list[int],
                 key: str = "achieved") -> list[list[float]]:
    """One row per run of ``names`` in the ``lane`` setting, one 0/1 column per episode seed of ``order``: ``key``
    ('survived' or 'achieved'). The shape :func:`laneshift.tools.studies.stats.paired_difference_ci` takes."""
    return [[float(getattr(runs[(name, lane)][e], key)) for e in order] for name in names]


def achievement_by_start_lane(runs: Outcomes, names: list[str],
                              lane: str = "non-target") -> dict[int, tuple[float, int]]:
    """{start lane: (achievement rate of ``names``' episodes pooled, episodes per run)} in the ``lane`` setting: where
    the studies' tables split a setting by the lane an episode starts in (merge: the fast lane 0, the on-ramp 2)."""
    starts = sorted({o.start_lane for name in names for o in runs[(name, lane)].values()})
    out = {}
    for start in starts:
        hits = [o.achieved for name in names for o in runs[(name, lane)].values() if o.start_lane == start]
        out[start] = (sum(hits) / len(hits), len(hits) // len(names))
    return out
