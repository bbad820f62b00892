#!/bin/bash
# Straight road, dqfd-bc-alongside-safe-shield with the imitation losses fading to 0 over phase 2
# (learner.imitation_final=0): three seeds, 600,000 env steps each, behind the shield, the final
# networks on 200 test and 200 validation episodes per setting. Ran from a checkout at revision
# d065f9c (docs/RESULTS.md, "Past the teacher"); published under results/checkpoints/straight-imfade-*.
laneshift experiment protocol --scenario straight --method dqfd-bc-alongside-safe-shield --env-steps 600000 \
  --seeds 0,1,2 --set learner.imitation_final=0 --final-validation-episodes 200 \
  --road straight-imfade --out runs/protocol/straight-imfade0-600k --publish results/checkpoints
