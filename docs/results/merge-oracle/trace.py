"""Merge: four of the validation episodes no agent solved, traced: the driver, the published network of seed 0
and the constant-speed plan that solved it; steps on which the shield called the right lane free while in lane 0,
and the speed every 30 steps (* off lane 0). Run from the repository root.

Room: a study's script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import sys
sys.path.insert(0, "docs/results/merge-oracle")
from oracle import SpeedPlan, ENV, make, load_greedy_policy, CHECKPOINTS
from laneshift.actors.envs.demonstrator import ScriptedDriver
net = load_greedy_policy(CHECKPOINTS.format(0))
env = make(ENV); u = env.unwrapped
for seed, v in ((200012, 11), (200021, 12), (200038, 14), (200040, 10)):
    for who in ("driver", "net", "plan"):
        obs, info = env.reset(seed=seed)
        pol = ScriptedDriver(u) if who == "driver" else net if who == "net" else SpeedPlan(u, v, v, 0, False)
        sp = []; free = 0; done = False; t = 0
        while not done:
            slots = u.lane_slots(u.ego); free += u.gap_shield.lane_free(slots[2]) if u.ego.loc.lane == 0 else 0
            if t % 30 == 0: sp.append(f"{u.ego.speed:.0f}{'' if u.ego.loc.lane == 0 else '*'}")
            obs, r, te, tr, info = env.step(int(pol(obs))); done = te or tr; t += 1
        print(seed, who, "free steps in lane 0:", free, "speeds:", " ".join(sp), "end lane", info["lane_index"])
