#!/bin/bash
# Seed-0 probes of learner.imitation_final=0 (the imitation losses fading to 0 over phase 2) on each
# road's published recipe behind the shield, 400,000 env steps, judged on 200 validation episodes per
# setting (docs/RESULTS.md, "Past the teacher"). Ran from a checkout at revision d065f9c. Merge's
# table is here (merge-table.md, merge-results.json); policy traffic's and the roundabout's seed 0
# are part of their three-seed folders (straight-policytraffic-imfade-400k/, roundabout-imfade-400k/).
# The curve's probe was stopped unrun for time.
p="laneshift experiment protocol --final-validation-episodes 200 --set learner.imitation_final=0 --seeds 0"
$p --scenario merge --method dqfd-bc-alongside-gaps-safe-shield --env-steps 400000 --set env.max_steps=300 \
  --road merge-imfade --out runs/protocol/merge-gaps-imfade0-400k
$p --scenario straight --method dqfd-bc-alongside-safe-shield --env-steps 400000 --set env.policy_vehicles=3 \
  --set env.max_steps=300 --road straight-policytraffic-imfade --out runs/protocol/straight-policytraffic-imfade0-400k
$p --scenario roundabout --method dqfd-bc-alongside-safe-shield --env-steps 400000 --set env.max_steps=300 \
  --road roundabout-imfade --out runs/protocol/roundabout-imfade0-400k
