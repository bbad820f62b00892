#!/bin/bash
# Pixel probe 9 (docs/RESULTS.md, pixels on the converging learner): probe 7 (../pixels-probe-fi4-150k/run.sh:
# probe 1's recipe on frames stacked 4 policy steps apart) with the ego at 0.3 of the frame's width
# (env.frame_centering=0.3, highway-env's place: 35 m of road ahead in view instead of 25), seed 0, 150,000
# env steps. Ran 2026-11-27 from a checkout at revision 8527220, beside a fresh clone's `make test` for 13 of
# its minutes (its pre-training slowed to ~4 updates/s then); its demo shard (drawn the same way) and the
# baselines are made by the command itself.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi4-c03-150k \
  --set env.observation=grayscale --set env.frame_interval=4 --set env.frame_centering=0.3 \
  --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=8 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Where its network crashes (40 validation episodes from a random lane; crash_geometry-seed0.log):
python ../pixels-probe-400k/crash_geometry.py \
  runs/protocol/straight-pixels-fi4-c03-150k/dqfd-bc-anneal-s0/checkpoints/final.safetensors 40
