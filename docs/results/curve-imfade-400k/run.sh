#!/bin/bash
# Curve, dqfd-bc-alongside-safe-shield with the imitation losses fading to 0 over phase 2
# (learner.imitation_final=0): three seeds, 400,000 env steps, behind the shield, final networks on 200
# test and 200 validation episodes per setting. Ran from a checkout at revision d065f9c (seed 0's probe
# was stopped in its pre-training one session and continued by this same command the next); published
# under results/checkpoints/curve-imfade-* (docs/RESULTS.md, "Past the teacher").
laneshift experiment protocol --scenario curve --method dqfd-bc-alongside-safe-shield --env-steps 400000 \
  --set env.max_steps=300 --seeds 0,1,2 --set learner.imitation_final=0 --final-validation-episodes 200 \
  --road curve-imfade --out runs/protocol/curve-imfade0-400k --publish results/checkpoints
