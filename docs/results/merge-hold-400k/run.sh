#!/bin/bash
# Issue 27, a shorter merge run: the merge recipe with exploration that holds its actions (actor.hold_mu=2, taken
# on 2026-11-29: docs/results/merge-pre60k-hold-400k/) but the method's own 20,000 pre-training updates instead of
# 60,000 (the 40,000 more take 4.5-7 minutes of a run, and put merge over the 15-minute bound on a slow day).
# Judged on the 200 validation episodes per setting, test held (--hold-test) until the choice is made.
# The rule (written 2026-11-29 before any seed ran): taken as merge's recipe (shorter) if the three seeds' validation
# achievement from a non-target lane is >= 91.5 on the mean and from a random lane >= 94.3 (1 point below the
# merge-pre60k networks' 95.3); else the 60,000 pre-training updates stay.
cd /work/study-w31  # a worktree of b648c38 (from a clone: drop the cd, run in the repository root)
.venv/bin/laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield \
  --env-steps 400000 --set env.max_steps=300 --seeds ${SEEDS:-1,2,0} \
  --set actor.hold_mu=2 --final-validation-episodes 200 --hold-test \
  --road merge-hold --out /work/study-w31/runs/protocol/merge-hold-400k
