#!/bin/bash
# Pixel probe 4 (docs/RESULTS.md, pixels on the converging learner): probe 1's recipe
# (../pixels-probe-150k/run.sh) with twice its sampled rows per env step (replay.samples_per_insert 16: one
# update of 32 per 2 env steps), seed 0, 150,000 env steps. Ran 2026-11-27 from a checkout at revision
# ee0373a (frames cast once, 1/255 folded into the first convolution), alone on the 2-core machine but for
# two niced 40-episode diagnostics and the test of three GPU networks: 61.5 minutes in all.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-spi16-150k \
  --set env.observation=grayscale --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=16 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
