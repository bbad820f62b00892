"""Probe: starts on merge's on-ramp (validation episodes from 200,000, random lane), a network
behind the shield against the scripted driver behind it: speed at 150, 100, 60 and 30 m before the
ramp's end, where each leaves the ramp, and the misses (docs/RESULTS.md, "where the gap is")::

    python ramp_probe.py CHECKPOINT [EPISODES]     # the episodes scanned for ramp starts (120)

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
import numpy as np
from laneshift.actors.envs import make
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig

ck = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 120
cfg = EnvConfig(scenario="merge", max_steps=300, alongside_features=True, shield=True, initial_lane="random")
pol = load_greedy_policy(ck)
env = make(cfg)
for who in ("network", "driver"):
    rows = []
    for ep in range(n):
        obs, info = env.reset(seed=200000 + ep)
        if info["lane_index"] != 2:
            continue
        u = env.unwrapped
        act = pol if who == "network" else ScriptedDriver(env)
        marks = {}
        left_at = None; sh = 0; done = False; t = 0
        while not done:
            a = act(obs) if who == "network" else act()
            obs, r, te, tr, info = env.step(a); t += 1; done = te or tr
            sh += info.get("shielded", 0)
            le = u.ego.loc.lane_end
            for m in (150, 100, 60, 30):
                if m not in marks and le <= m and info["lane_index"] == 2:
                    marks[m] = round(u.ego.speed, 1)
            if left_at is None and info["lane_index"] != 2:
                left_at = (t, round(float(le) if np.isfinite(le) else -1, 0), round(u.ego.speed, 1))
        rows.append((ep, marks, left_at, info["crashed"], info["on_target_lane"], sh, u.lane_speeds[1]))
    ok = sum(1 for r in rows if not r[3] and r[4])
    print(f"{who}: {len(rows)} ramp starts, {ok} on target; mean speed at ramp left 150/100/60/30 m:",
          {m: round(np.mean([r[1][m] for r in rows if m in r[1]]), 2) for m in (150, 100, 60, 30)})
    for r in rows:
        if r[3] or not r[4]:
            print("  miss", r)
    print("  hits sample", rows[:4])
