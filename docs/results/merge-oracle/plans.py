"""Merge, validation episodes from a non-target lane: one constant-speed plan of oracle.py (steering into the
target lane whenever the shield calls it free) on all 200; run from the repository root.

Room: a study's script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
sys.path.insert(0, "docs/results/merge-oracle")
from oracle import SpeedPlan, drive, ENV, make
env = make(ENV); u = env.unwrapped
for v in (10, 11, 12, 13, 14):
    res = {0: [0, 0], 2: [0, 0]}
    for ep in range(200):
        obs, info = env.reset(seed=200000 + ep)
        r = drive(u, SpeedPlan(u, v, v, 0, False), obs)
        res[info["lane_index"]][0] += r["achieved"]; res[info["lane_index"]][1] += 1
    tot = sum(a for a, _ in res.values())
    print(v, "achieved", tot / 2, "% ; by start lane", res, flush=True)
