#!/bin/bash
# The published straight networks (dqfd-bc-alongside-safe-shield, 600,000 env steps, seeds 0-2) and
# the scripted driver behind the same shield on the VALIDATION episodes (seeds 200,000-200,199, 300
# steps, 200 per initial-lane setting): what a new straight recipe is compared with (docs/RESULTS.md,
# "Three seeds on the straight road"). From the repository's root:
#   bash docs/results/straight-published-validation/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT"
common="--episodes 200 --seed 200000 --max-steps 300 --json"
for lane in random non-target; do
  for s in 0 1 2; do
    laneshift eval --checkpoint results/checkpoints/straight-dqfd-bc-alongside-safe-shield-seed$s-final.safetensors \
      $common --initial-lane $lane --episodes-out "$OUT/base-s$s-$lane.jsonl" > "$OUT/base-s$s-$lane.json"
  done
  laneshift eval --driver scripted --scenario straight --set env.shield=true $common --initial-lane $lane \
    --episodes-out "$OUT/driver-$lane.jsonl" > "$OUT/driver-$lane.json"
done
