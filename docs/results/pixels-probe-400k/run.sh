#!/bin/bash
# Pixel probe 3 (docs/RESULTS.md, pixels on the converging learner): probe 1's recipe
# (docs/results/pixels-probe-150k/run.sh) at 400,000 env steps, seed 0. Ran from a checkout at
# revision b7ce204; the network: results/checkpoints/straight-pixels-400k-dqfd-bc-anneal-seed0-final.*
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 400000 --road straight-pixels --out runs/protocol/straight-pixels-dqfd-bc-anneal-400k \
  --set env.observation=grayscale --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=8 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16 --publish runs/publish
