#!/bin/bash
# The pixel probes of docs/RESULTS.md (pixels on the converging learner), seed 0, validation for
# every choice. Probe 1 (results.json, table.md here): dqfd-bc-anneal on 4 x 100 x 100 frames,
# SmallCNN with bf16 convolutions, DrQ's shift, batch 32, one update per 4 env steps.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-dqfd-bc-anneal-150k \
  --set env.observation=grayscale --set learner.cnn=small --set learner.batch_size=32 \
  --set replay.samples_per_insert=8 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16
# Offline imitation probes (a few minutes each, one core):
python view_probe.py 60 3000           # frames at 2 and 1 px/m against the vector observation
python bc_step_shift_probe.py 4000     # step size 1e-4 / 5e-4, with and without the shift
python bc_drive_probe.py 120 8000 40   # does the pixel classifier drive? (and: ... vector)
python bc_drive_probe.py 120 8000 40 vector
# Probe 2 (probe2-validation.json; stopped at 73,600 env steps, its validation flat at 10 %): twice the
# sampled rows per env step, no shift, 10,000 pre-training updates of 64.
laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels --out runs/protocol/straight-pixels-b64-dqfd-bc-anneal-150k \
  --set env.observation=grayscale --set learner.cnn=small --set learner.batch_size=64 \
  --set replay.samples_per_insert=16 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.phase1_updates=10000 --set learner.cnn_precision=bf16
