#!/bin/bash
# Pixel probe 7 (docs/RESULTS.md, pixels on the converging learner): probe 1's recipe
# (../pixels-probe-150k/run.sh: batch 32, 8 sampled rows per env step) on frames stacked 4 policy steps apart
# (env.frame_interval=4: the frames at t, t-4, t-8, t-12, 1.2 s across the stack instead of 0.3 s), seed 0,
# 150,000 env steps. Ran 2026-11-27 from a checkout at revision cc6a58c (the machine otherwise idle but for
# the quick test suite, niced, for 3.5 of its minutes); its demo shard (stacked the same way) and the
# baselines are made by the command itself.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi4-150k \
  --set env.observation=grayscale --set env.frame_interval=4 --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=8 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Where its network crashes (40 validation episodes from a random lane; crash_geometry-seed0.log):
python ../pixels-probe-400k/crash_geometry.py \
  runs/protocol/straight-pixels-fi4-150k/dqfd-bc-anneal-s0/checkpoints/final.safetensors 40
