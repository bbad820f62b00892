#!/bin/bash
# Pixel probe 14 (docs/RESULTS.md, pixels on the converging learner): probe 13 (frames 8 steps apart, the CNN on the
# road's band, 32 sampled rows per env step) with three times the pre-training (learner.phase1_updates=60000:
# 1.92 M demo rows against 0.64 M), seed 0, 150,000 env steps; revision 8029542, from a frozen checkout.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi8-rows-spi32-pre60k-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 --set learner.phase1_updates=60000 \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Seed 0 ran 2026-11-28 from a frozen checkout, its demo shard probe 13's (hard-linked in; the command makes it when
# missing); its phase 1 partly beside a py-spy profile and a micro-benchmark (docs/results/pixels-shift-numpy/).
# Published with the same command and --road straight-pixels-fi8-rows-pre60k --publish results/checkpoints.
# Its final network on the 200 validation episodes per setting (2026-11-28, a later session, for the comparison with
# probe 15): the same command with --road straight-pixels-fi8-rows --final-validation-episodes 200 (no retraining;
# results.json and table.md here are that command's).
