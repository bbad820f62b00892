"""Probe: greedy on the mean (or min, or a vote) of several networks' Q-values, on 200 validation
episodes per initial-lane setting (seeds from 200,000; docs/RESULTS.md, "behind a safety shield")::

    python ensemble_probe.py ROAD mean|min|vote OUT.json CHECKPOINT...

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""
import json, sys, dataclasses
import numpy as np
from laneshift.actors.evaluation import load_checkpoint_policy, evaluate_lanes
from laneshift.config import EnvConfig

road, how, out, *ckpts = sys.argv[1:]
nets = [load_checkpoint_policy(c).policy for c in ckpts]

class Ens:
    def __call__(self, obs):
        qs = np.stack([n.q(np.asarray(obs, np.float32)[None])[0] for n in nets])
        q = qs.mean(0) if how == "mean" else qs.min(0) if how == "min" else None
        if how == "vote":
            votes = np.bincount(qs.argmax(1), minlength=qs.shape[1]); q = votes + 1e-3 * qs.mean(0)
        return int(np.argmax(q))

env = EnvConfig(scenario=road, max_steps=300, alongside_features=True)
r = evaluate_lanes(lambda e: Ens(), env, 200, 200000)
json.dump(r, open(out, "w"), indent=1)
for lane, e in r.items():
    print(road, how, lane, e["survival_rate"], e["achievement_rate"], e["crashes"])
