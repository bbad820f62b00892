#!/bin/bash
# Roundabout, dqfd-bc-alongside-safe-shield with the imitation losses fading to 0 over phase 2
# (learner.imitation_final=0): three seeds, 400,000 env steps, behind the shield, final networks on 200
# test and 200 validation episodes per setting. Ran from a checkout at revision d065f9c (seed 0 first as
# a probe, then seeds 1-2 by the same command); published under results/checkpoints/roundabout-imfade-*
# (docs/RESULTS.md, "Past the teacher").
laneshift experiment protocol --scenario roundabout --method dqfd-bc-alongside-safe-shield --env-steps 400000 \
  --set env.max_steps=300 --seeds 0,1,2 --set learner.imitation_final=0 --final-validation-episodes 200 \
  --road roundabout-imfade --out runs/protocol/roundabout-imfade0-400k --publish results/checkpoints
