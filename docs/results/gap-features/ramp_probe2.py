"""Probe: a network's misses from merge's on-ramp (validation episodes, shield on): on each step of
the ramp's last 160 m, is the main road's lane free by the shield's rule, is a car alongside, does
the network steer towards it, does it speed up or slow down::

    python ramp_probe2.py CHECKPOINT 3,6,10,18,41      # validation episode numbers (seed 200,000 + n)

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
import numpy as np
from laneshift.actors.envs import make
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
ck = sys.argv[1]; eps = [int(x) for x in sys.argv[2].split(",")]
env = make(EnvConfig(scenario="merge", max_steps=300, alongside_features=True, shield=True, initial_lane="random"))
pol = load_greedy_policy(ck)
for ep in eps:
    obs, info = env.reset(seed=200000 + ep); u = env.unwrapped
    stats = dict(steps=0, free=0, alongside=0, left_try=0, left_try_free=0, faster=0, slower=0)
    done = False
    while not done:
        a = int(pol(obs))
        slots = u.lane_slots(u.ego)
        on_ramp = u.ego.loc.lane == 2 and u.ego.loc.lane_end < 160
        if on_ramp:
            stats["steps"] += 1
            free = u.gap_shield.lane_free(slots[1]); stats["free"] += free
            stats["alongside"] += slots[1] is not None and min(slots[1][0], slots[1][2]) < 0
            sp, cu = divmod(a, 3)
            stats["left_try"] += cu == 1; stats["left_try_free"] += cu == 1 and free
            stats["faster"] += sp == 1; stats["slower"] += sp == 2
        obs, r, te, tr, info = env.step(a); done = te or tr
    print(ep, stats, "end lane", info["lane_index"], "speed", round(u.ego.speed, 1))
