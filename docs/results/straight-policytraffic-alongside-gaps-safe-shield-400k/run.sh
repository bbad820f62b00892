#!/bin/bash
# Straight road with 3 vehicles driven by the network under test, trained with the gap features
# behind the shield (docs/RESULTS.md, "Policy traffic with the gap features"). Seeds 0 and 1 ran
# to the end; seed 2 was stopped for time (2026-11-27), so there is no results.json or table.md,
# only each seed's record (test and validation rates). From the repository's root:
#   bash docs/results/straight-policytraffic-alongside-gaps-safe-shield-400k/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
laneshift experiment protocol --scenario straight --method dqfd-bc-alongside-gaps-safe-shield --seeds 0,1 \
  --env-steps 400000 --set env.policy_vehicles=3 --set env.max_steps=300 --final-validation-episodes 200 --out "$OUT"
# The published policy-traffic networks (trained behind the shield without the gap features) on
# the same validation episodes: published-validation/.
for s in 0 1 2; do
  for lane in random non-target; do
    laneshift eval --checkpoint results/checkpoints/straight-policytraffic-dqfd-bc-alongside-safe-shield-seed$s-final.safetensors \
      --scenario straight --set env.policy_vehicles=3 --episodes 200 --seed 200000 --max-steps 300 \
      --initial-lane $lane --json > "$OUT/pt-base-s$s-$lane.json"
  done
done
