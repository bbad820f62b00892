#!/bin/bash
# Pixel probe 12 (docs/RESULTS.md, pixels on the converging learner): probe 11's command
# (../pixels-probe-fix-fi4-spi16-150k/run.sh) with the CNN on the straight road's band (learner.cnn_rows=22:78,
# about 1.65x the updates a second) and twice the sampled rows per env step (replay.samples_per_insert=32: one
# update of 32 per env step). Seed 0 ran 2026-11-28 at revision 8029542 from a frozen checkout, its demo shard
# probe 7's (copied in; the command makes it when missing); 45 of its 76 minutes beside the behaviour-cloning
# study (../pixels-bc-diagnostic/).
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-fi4-rows-spi32-150k \
  --set env.observation=grayscale --set env.frame_interval=4 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Where seed 0's network crashes (40 validation episodes from a random lane; crash_geometry-seed0.log):
python ../pixels-probe-400k/crash_geometry.py \
  runs/protocol/straight-pixels-fi4-rows-spi32-150k/dqfd-bc-anneal-s0/checkpoints/final.safetensors 40
