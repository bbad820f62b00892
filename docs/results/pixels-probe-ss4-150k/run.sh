#!/bin/bash
# Pixel probe 6 (docs/RESULTS.md, pixels on the converging learner): probe 1's recipe
# (../pixels-probe-150k/run.sh: batch 32, 8 sampled rows per env step) on anti-aliased frames
# (env.frame_supersample=4), seed 0, 150,000 env steps. Ran 2026-11-27 from a checkout at revision 38de153
# (whose block sums took 4 ms a frame; 20c6abb computes the same integers in 0.2 ms), beside a fresh clone's
# test suite for 25 of its minutes; its demo shard (drawn the same way) and the baselines are made by the
# command itself.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-ss4-150k \
  --set env.observation=grayscale --set env.frame_supersample=4 --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=8 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# What anti-aliased frames cost the env (a quiet machine): env steps/s at frame_supersample 1, 2, 4.
python render_cost.py --steps 1000 --rounds 3
