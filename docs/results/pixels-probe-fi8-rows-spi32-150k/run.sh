#!/bin/bash
# Pixel probe 13 (docs/RESULTS.md, pixels on the converging learner): probe 12 (the CNN on the road's band,
# 32 sampled rows per env step) with frames 8 steps apart (env.frame_interval=8; probe 12: 4), seed 0,
# 150,000 env steps; revision 8029542, from a frozen checkout.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi8-rows-spi32-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Seed 0 ran 2026-11-28 from a frozen checkout, its demo shard the fi8 one of an earlier stopped probe (copied in;
# the command makes it when missing); about 25 of its 72 minutes beside the imitation study and a test suite.
