"""Merge's missed validation episodes from a non-target lane, the network against the scripted driver
on the same episodes: which misses they share (episodes neither solves here), which only one of them
misses, and where each miss started (lane 0, the fast lane; lane 2, the on-ramp) and how it ended.
Reads the ``laneshift eval --episodes-out`` files ``seed0.jsonl`` and ``driver.jsonl`` that ``run.sh``
made; writes ``table.md``.

    python docs/results/merge-misses/summarise.py OUT_DIR

Room: a study's script (docs/results). May import: the standard library.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(out: Path) -> None:
    runs = {who: [json.loads(line) for line in (out / f"{who}.jsonl").read_text().splitlines() if line.strip()]
            for who in ("seed0", "driver")}
    assert [o["seed"] for o in runs["seed0"]] == [o["seed"] for o in runs["driver"]], "not the same episodes"
    by_seed = {who: {o["seed"]: o for o in eps} for who, eps in runs.items()}
    missed = {who: {o["seed"]: o for o in eps if not o["achieved"]} for who, eps in runs.items()}
    net, drv = missed["seed0"], missed["driver"]
    groups = {"missed by both": sorted(set(net) & set(drv)), "missed by the network only": sorted(set(net) - set(drv)),
              "missed by the driver only": sorted(set(drv) - set(net))}
    n = len(runs["driver"])
    lines = [f"{n} validation episodes from a non-target lane; achievement: network (seed 0) "
             f"{100 * (n - len(net)) / n:.1f} %, driver {100 * (n - len(drv)) / n:.1f} %", "",
             "| episodes | count | started in lane 0; lane 2 | crashed (network; driver) | the network never changed lane |",
             "|---|---|---|---|---|"]
    for name, seeds in groups.items():
        starts = [by_seed["driver"][s]["start_lane"] for s in seeds]
        crashed = (sum(not by_seed["seed0"][s]["survived"] for s in seeds),
                   sum(not by_seed["driver"][s]["survived"] for s in seeds))
        stayed = sum(not by_seed["seed0"][s]["lane_changes"] for s in seeds)
        lines.append(f"| {name} | {len(seeds)} | {starts.count(0)}; {starts.count(2)} | {crashed[0]}; {crashed[1]} | {stayed} |")
    (out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
