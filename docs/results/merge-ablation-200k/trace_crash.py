"""Trace a merge episode from the on-ramp: the network, then the scripted driver, step by step (the
last 12 steps of a crash). A diagnostic of docs/RESULTS.md (merge), not part of the product.

    python trace_crash.py CHECKPOINT EPISODE_SEED   (the checkpoint of the 82-float observation)

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch.
"""
import sys, numpy as np
from laneshift.actors.envs import make
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
ck, seed = sys.argv[1], int(sys.argv[2])
for who in ("net", "driver"):
    env = make(EnvConfig(scenario="merge", max_steps=300)); u = env.unwrapped
    pol = load_greedy_policy(ck) if who == "net" else ScriptedDriver(env)
    obs, info = env.reset(seed=seed, options={"initial_lane": 2}); done = False; t = 0; rows = []
    while not done:
        a = int(pol(obs)); e = u.ego; loc = e.loc
        f1, vf1, r1, vr1 = u.lane_neighbours(e, 1)
        rows.append(f"t{t:3d} a{a} lane{loc.lane} lat2={loc.lat[2]:+.2f} v={e.speed:.1f} end={loc.lane_end:6.1f} L1 front {f1:6.1f}@{vf1:4.1f} rear {r1:6.1f}@{vr1:4.1f}")
        obs, r, term, trunc, info = env.step(a); t += 1; done = term or trunc
    print(who, "crashed" if term else "ok", info.get("collided"), info.get("offroad"))
    for row in rows[-12:] if term else rows[70:120:5]: print("  ", row)
