"""Merge, validation episodes from a non-target lane: the scripted driver changing lane when its own gap rule or
the shield's rule calls the lane free ("or"), or the shield's alone; run from the repository root.

Room: a study's script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
sys.path.insert(0, "docs/results/merge-oracle")
from oracle import drive, ENV, make
from laneshift.actors.envs.demonstrator import ScriptedDriver
class Hybrid(ScriptedDriver):
    mode = "or"
    def _gap_safe(self, lane):
        u = self.env; ego = u.ego
        side = 1 if u.adjacent_lane(ego, -1) == lane else 2 if u.adjacent_lane(ego, +1) == lane else None
        free = side is not None and u.gap_shield.lane_free(u.lane_slots(ego)[side])
        if self.mode == "shield": return free
        return free or super()._gap_safe(lane)
env = make(ENV); u = env.unwrapped
for mode in ("or", "shield"):
    res = {0: [0, 0], 2: [0, 0]}; surv = 0
    for ep in range(200):
        obs, info = env.reset(seed=200000 + ep)
        d = Hybrid(u); d.mode = mode
        r = drive(u, d, obs)
        res[info["lane_index"]][0] += r["achieved"]; res[info["lane_index"]][1] += 1; surv += r["survived"]
    print(mode, "achieved", sum(a for a, _ in res.values()) / 2, "survived", surv / 2, res, flush=True)
