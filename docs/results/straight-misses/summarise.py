"""The straight road's missed test episodes from a non-target lane, episode by episode: for each
shield setting, which episodes each network (3 seeds) and the scripted driver end outside the
target lane, which of those all three networks miss, which the driver misses too, and how far a
missed episode got (its start and end lane). Writes ``table.md`` and ``misses.json`` beside the
``laneshift eval --episodes-out`` files that ``run.sh`` made.

    python docs/results/straight-misses/summarise.py OUT_DIR

Room: a study's script (docs/results). May import: the standard library.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

SETTINGS = {"gap3.0-decel0.9": "3 m / 0.9 m/s² (trained with)", "gap2.0-decel1.0": "2 m / 1.0 m/s² (chosen on validation)"}
SEEDS = (0, 1, 2)


def read(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def misses(episodes: list[dict]) -> dict[int, dict]:
    """The episodes that did not end in the target lane, by reset seed."""
    return {o["seed"]: o for o in episodes if not o["achieved"]}


def main(out: Path) -> None:
    rows, report = [], {}
    for tag, label in SETTINGS.items():
        nets = {s: read(out / f"seed{s}-{tag}.jsonl") for s in SEEDS}
        driver = read(out / f"driver-{tag}.jsonl")
        n = len(driver)
        assert all([o["seed"] for o in eps] == [o["seed"] for o in driver] for eps in nets.values()), \
            "the networks and the driver must have played the same episodes"
        missed = {s: misses(eps) for s, eps in nets.items()}
        by_driver = set(misses(driver))
        every_net = set.intersection(*(set(m) for m in missed.values()))
        any_net = set.union(*(set(m) for m in missed.values()))
        crashed = {s: sum(not o["survived"] for o in eps) for s, eps in nets.items()}
        # Where the networks' misses ended: a lane next to the target (one change short) or further.
        ends = {}
        for s, m in missed.items():
            for o in m.values():
                key = "crashed" if not o["survived"] else f"ended in lane {o['end_lane']} (started {o['start_lane']})"
                ends[key] = ends.get(key, 0) + 1
        # Achievement by starting lane: from lane 2 the target (lane 0) is two changes away.
        by_start = {}
        for who, eps in [*((f"seed {s}", e) for s, e in nets.items()), ("driver", driver)]:
            for lane in sorted({o["start_lane"] for o in driver}):
                mine = [o for o in eps if o["start_lane"] == lane]
                by_start.setdefault(f"start lane {lane} ({len(mine)} episodes)", {})[who] = \
                    round(100 * sum(o["achieved"] for o in mine) / len(mine), 1)
        shared = sum(len(set(m) & by_driver) for m in missed.values())
        total = sum(map(len, missed.values()))
        report[tag] = {"episodes": n, "achievement_by_start_lane": by_start, "missed_by_seed": {s: sorted(m) for s, m in missed.items()},
                       "missed_by_driver": sorted(by_driver), "missed_by_every_network": sorted(every_net),
                       "missed_by_some_network": sorted(any_net),
                       "missed_by_every_network_and_the_driver": sorted(every_net & by_driver),
                       "network_misses_the_driver_also_misses": shared,
                       "network_crashes": crashed, "where_network_misses_ended": ends}
        per_seed = ", ".join(str(len(missed[s])) for s in SEEDS)
        rows.append(f"| {label} | {per_seed} ({total} in all) | {len(by_driver)} | {len(every_net)} | "
                    f"{len(every_net & by_driver)} | {shared} of {total} | {len(any_net | by_driver)} |")
    table = ["| shield | missed by seed 0, 1, 2 | missed by the driver | missed by all 3 networks | "
             "... and by the driver | networks' misses the driver misses too | missed by any of the 4 |",
             "|---|---|---|---|---|---|---|", *rows]
    (out / "table.md").write_text("\n".join(table) + "\n")
    (out / "misses.json").write_text(json.dumps(report, indent=1) + "\n")
    print("\n".join(table))
    for tag, r in report.items():
        print(f"{tag}: where the networks' misses ended: {r['where_network_misses_ended']}; "
              f"network crashes {r['network_crashes']}; achievement by starting lane: {r['achievement_by_start_lane']}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
