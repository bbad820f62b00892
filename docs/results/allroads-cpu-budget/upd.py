"""``DoubleDQN.update`` alone on one CPU: ``LearnerConfig``'s defaults (what `laneshift bench learner`
times) against the allroads recipe's learner section, one change at a time, alternating 3 rounds of
3 s. A third of each batch is demonstration rows and the last four features a road one-hot, as in a
run of the recipe. From a checkout's root, on one CPU:

    taskset -c 1 .venv/bin/python docs/results/allroads-cpu-budget/upd.py \\
        docs/results/allroads-cpu-budget/allroads-heads-wide-bf16.yaml

Room: a study script (docs/results). May import: anything in laneshift.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np
import torch

from laneshift.config import LearnerConfig
from laneshift.config.loading import load_run_config
from laneshift.learner.dqn import DoubleDQN
from laneshift.tools.bench import learner as bench  # `laneshift bench learner`: its batches and Case

OBS_DIM, HEADS = 96, 4  # the allroads vector observation; its road one-hot ends it
torch.set_num_threads(1)
recipe = dataclasses.replace(load_run_config(sys.argv[1]).learner, device="cpu")
defaults = dataclasses.replace(LearnerConfig(device="cpu"), hidden=(512, 512), mlp_precision="bf16")
variants = {
    "bench": defaults,
    "run": recipe,
    "run-ema0": dataclasses.replace(recipe, ema_decay=0.0),
    "run-heads1": dataclasses.replace(recipe, heads=1),
    "run-fp32": dataclasses.replace(recipe, mlp_precision="fp32"),
}
keys = ("dueling", "heads", "n_step", "margin_loss_weight", "bc_loss_weight", "ema_decay", "lr_final", "batch_size")
for name in ("bench", "run"):
    print(name, {k: getattr(variants[name], k) for k in keys})

sampled = bench.sampled_batch(bench.Case("x", (OBS_DIM,), "float32", 256, precision="bf16", hidden=(512, 512)), 4)
n = len(sampled.is_demo)
sampled.is_demo[: int(0.3 * n)] = 1
sampled.obs[:, -HEADS:] = 0
sampled.obs[np.arange(n), OBS_DIM - HEADS + np.arange(n) % HEADS] = 1
sampled.next_obs[:, -HEADS:] = sampled.obs[:, -HEADS:]
parts = bench._split(sampled)

agents = {name: DoubleDQN((OBS_DIM,), 9, cfg) for name, cfg in variants.items()}
rates: dict[str, list[float]] = {name: [] for name in agents}
for _ in range(3):
    for name, agent in agents.items():
        for p in parts[:2]:
            agent.update(p)
        began, k = time.perf_counter(), 0
        while time.perf_counter() - began < 3:
            agent.update(parts[k % len(parts)])
            k += 1
        rates[name].append(k / (time.perf_counter() - began))
for name, r in rates.items():
    print(f"{name:12s} {np.mean(r):7.1f} upd/s  {['%.1f' % x for x in r]}")
