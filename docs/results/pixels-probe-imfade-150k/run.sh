#!/bin/bash
# Pixel probe 15 (docs/RESULTS.md, pixels on the converging learner): probe 14 (frames 8 steps apart, the CNN on the
# road's band, 32 sampled rows per env step, 60,000 pre-training updates) with the imitation losses fading to nothing
# over phase 2 (learner.imitation_final=0, the recipe that took the curve past its driver), seed 0, 150,000 env
# steps; revision d065f9c, from a frozen checkout.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels-fi8-rows-pre60k-imfade --out runs/protocol/straight-pixels-fi8-rows-pre60k-imfade-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 --set learner.phase1_updates=60000 \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16 --set learner.imitation_final=0 \
  --final-validation-episodes 200
# Ran 2026-11-28, paused at 68,704 env steps (after its pre-training) and resumed with the same command; its demo
# shard probe 13's (hard-linked in; the command makes it when missing). Not published: below probe 14 on validation.
