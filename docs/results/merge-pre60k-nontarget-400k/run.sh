#!/bin/bash
# Issue 27, merge from a non-target lane (1.0 point short): the published recipe (merge-pre60k:
# dqfd-bc-alongside-gaps-safe-shield, 60,000 pre-training updates, 400,000 env steps) with every
# training episode and every demonstration started outside the target lane (env.initial_lane=non-target).
# Judged on the 200 validation episodes per setting against the published networks' validation
# rates (docs/results/merge-pre60k-400k/table.md); the test rows are not read for the choice.
cd /work/study-w30  # a worktree of 8039281 (from a clone: drop the cd, run in the repository root)
.venv/bin/laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield \
  --env-steps 400000 --set env.max_steps=300 --seeds ${SEEDS:-1,2,0} --set learner.phase1_updates=60000 \
  --set env.initial_lane=non-target --final-validation-episodes 200 \
  --road merge-pre60k-nontarget --out /work/study-w30/runs/protocol/merge-pre60k-nontarget-400k
