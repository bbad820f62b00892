#!/bin/bash
# Pixel probe 11 (docs/RESULTS.md, pixels on the converging learner): probe 10's command
# (../pixels-probe-fi4-spi16-150k/run.sh) at revision 190eea7, where the replay stores about one frame an item
# (probe 10's table had held 43,000 of its 140,000 items: replay_stats-seed0.json in both folders). Seed 0 ran
# 2026-11-28 from a frozen checkout, its demo shard probe 7's (copied in; the command makes it when missing);
# seed 1 was added by the same command with --seeds 0,1 (the finished seed is skipped).
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0,1 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi4-spi16-150k-fix \
  --set env.observation=grayscale --set env.frame_interval=4 --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=16 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Where seed 0's network crashes (40 validation episodes from a random lane; crash_geometry-seed0.log):
python ../pixels-probe-400k/crash_geometry.py \
  runs/protocol/straight-pixels-fi4-spi16-150k-fix/dqfd-bc-anneal-s0/checkpoints/final.safetensors 40
