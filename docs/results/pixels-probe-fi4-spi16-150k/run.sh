#!/bin/bash
# Pixel probe 10 (docs/RESULTS.md, pixels on the converging learner): probe 7 (../pixels-probe-fi4-150k/run.sh:
# probe 1's recipe on frames stacked 4 policy steps apart) with twice the sampled rows per env step
# (replay.samples_per_insert=16: one update of 32 per 2 env steps, probe 4's), seed 0, 150,000 env steps;
# chosen over probe 9's off-centre frame on validation episodes. Ran 2026-11-27 from a checkout at revision
# cc6a58c, the machine otherwise idle; its demo shard was probe 7's, copied in before it ran (the same env and
# episode seeds make the same rows; the command makes it when it is missing), the baselines made by the command.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi4-spi16-150k \
  --set env.observation=grayscale --set env.frame_interval=4 --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=16 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Where its network crashes (40 validation episodes from a random lane; crash_geometry-seed0.log):
python ../pixels-probe-400k/crash_geometry.py \
  runs/protocol/straight-pixels-fi4-spi16-150k/dqfd-bc-anneal-s0/checkpoints/final.safetensors 40
