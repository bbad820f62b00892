"""Probe: one straight-road episode from a non-target lane behind the shield (validation seed
200,000 + n), the network against the scripted driver, every 25 steps: lane, speed, action (speed,
curvature), whether the left lane is free by the shield's rule, the current and left lane slots::

    python straight_trace.py CHECKPOINT 0,3

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import sys
from laneshift.actors.envs import make
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
pol = load_greedy_policy(sys.argv[1])
env = make(EnvConfig(scenario="straight", max_steps=300, alongside_features=True, shield=True, initial_lane="non-target"))
for ep in map(int, sys.argv[2].split(",")):
    for who in ("network", "driver"):
        obs, info = env.reset(seed=200000 + ep); u = env.unwrapped
        d = ScriptedDriver(env) if who == "driver" else None
        done = False; t = 0; rows = []; sh = 0
        while not done:
            a = int(pol(obs)) if d is None else d()
            s = u.lane_slots(u.ego)
            rows.append((t, u.ego.loc.lane, round(u.ego.speed, 1), divmod(a, 3), u.gap_shield.lane_free(s[1]),
                         tuple(round(x, 1) for x in s[0]), tuple(round(x, 1) for x in (s[1] or ()))))
            obs, r, te, tr, info = env.step(a); done = te or tr; t += 1; sh += info.get("shielded", 0)
        print(ep, who, "end lane", info["lane_index"], "crashed", info["crashed"], "shielded", sh)
        for row in rows[::25]: print("   ", row)
