"""Probe: the shield's own figures (bumper gap kept, planning deceleration) on 200 validation
episodes per initial-lane setting, the published dqfd-bc-alongside-safe networks with the shield at
test (docs/RESULTS.md, "behind a safety shield")::

    python sweep_probe.py ROAD BUFFER_M DECEL OUT.json      # the driver's figures: 3 0.9

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import dataclasses, json, sys
from laneshift.actors.evaluation import evaluate_lanes, load_greedy_policy
from laneshift.config import EnvConfig
road, buffer, decel, out = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
res = {}
for s in range(3):
    pol = load_greedy_policy(f"results/checkpoints/{road}-dqfd-bc-alongside-safe-seed{s}-final.safetensors")
    def make(env):
        base = env.unwrapped
        base.gap_shield = dataclasses.replace(base.gap_shield, buffer=buffer, decel=decel)
        return pol
    r = evaluate_lanes(make, EnvConfig(scenario=road, max_steps=300, alongside_features=True, shield=True), 200, 200000)
    res[s] = {k: (v["survival_rate"], v["achievement_rate"]) for k, v in r.items()}
    print(road, buffer, decel, s, res[s], flush=True)
json.dump(res, open(out, "w"))
