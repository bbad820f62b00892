"""Probe: merge from a non-target lane with the gap features, the starts in the fast lane 0 that never
reach the target lane (validation episodes, shield on): every 15 steps the speed, the lane, the
right gap's middle [m], whether the right lane is free by the shield's rule, the action (speed,
curvature) and the right lane slot::

    python lane0_probe.py CHECKPOINT EPISODES_TO_SHOW

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
import numpy as np
from laneshift.actors.envs import make
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
pol = load_greedy_policy(sys.argv[1]); nshow = int(sys.argv[2])
env = make(EnvConfig(scenario="merge", max_steps=300, alongside_features=True, gap_features=True, shield=True, initial_lane="non-target"))
shown = 0
for ep in range(200):
    obs, info = env.reset(seed=200000 + ep); u = env.unwrapped
    if info["lane_index"] != 0: continue
    rows = []; done = False; t = 0
    while not done:
        a = int(pol(obs)); slots = u.lane_slots(u.ego)
        rows.append((t, round(u.ego.speed, 1), u.ego.loc.lane, round(float(obs[32 + 3]) * 50, 1),
                     u.gap_shield.lane_free(slots[2]), divmod(a, 3), tuple(round(x, 1) for x in (slots[2] or ())) ))
        obs, r, te, tr, info = env.step(a); done = te or tr; t += 1
    if info["lane_index"] == 0 and not info["crashed"]:
        print("episode", ep, "lane speeds", u.lane_speeds)
        for row in rows[::15]: print("  ", row)
        shown += 1
        if shown >= nshow: break
