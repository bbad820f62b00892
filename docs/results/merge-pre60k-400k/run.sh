#!/bin/bash
# Merge, dqfd-bc-alongside-gaps-safe-shield with three times the pre-training (learner.phase1_updates=60000:
# 1.92 M demo rows against 0.64 M), three seeds, 400,000 env steps, behind the shield, final networks on 200
# test and 200 validation episodes per setting. Ran from a checkout at revision d065f9c: seed 0 first as a
# probe (beside a second probe, the imitation loss twice as heavy, below), then seeds 1-2 by this command;
# published under results/checkpoints/merge-pre60k-* (docs/RESULTS.md, "Merge behind the shield").
laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield --env-steps 400000 \
  --set env.max_steps=300 --seeds 0,1,2 --set learner.phase1_updates=60000 --final-validation-episodes 200 \
  --road merge-pre60k --out runs/protocol/merge-gaps-pre60k-400k --publish results/checkpoints
# The other probe (seed 0, validation episodes decide; not carried):
# laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield --env-steps 400000 \
#   --set env.max_steps=300 --seeds 0 --set learner.bc_loss_weight=2 --final-validation-episodes 200 \
#   --road merge-bc2 --out runs/protocol/merge-gaps-bc2-400k
