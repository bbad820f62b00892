"""Probe: the straight road from a non-target lane behind the shield (validation episodes from
200,000): which episodes a network misses, which the scripted driver misses, and both::

    python straight_miss.py CHECKPOINT

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import sys
from laneshift.actors.envs import make
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
pol = load_greedy_policy(sys.argv[1])
env = make(EnvConfig(scenario="straight", max_steps=300, alongside_features=True, shield=True, initial_lane="non-target"))
miss = {"network": set(), "driver": set()}
for who in miss:
    for ep in range(200):
        obs, info = env.reset(seed=200000 + ep)
        d = ScriptedDriver(env) if who == "driver" else None
        done = False
        while not done:
            obs, r, te, tr, info = env.step(pol(obs) if d is None else d()); done = te or tr
        if info["crashed"] or not info["on_target_lane"]:
            miss[who].add(ep)
print("lane speeds example", env.unwrapped.lane_speeds)
print("network misses", sorted(miss["network"]))
print("driver misses", sorted(miss["driver"]))
print("both", sorted(miss["network"] & miss["driver"]))
