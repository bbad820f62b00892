#!/bin/bash
# The published allroads networks (dqfd-bc-alongside-gaps-safe-shield, 1,000,000 env steps, seeds
# 0-2) on each road's VALIDATION episodes (seeds 200,000-200,199, 300 steps, 200 per initial-lane
# setting, the road pinned with env.road): what a new allroads recipe is compared with
# (docs/RESULTS.md, "All four roads, one network"). The drivers on these episodes are in each
# protocol study's baselines-validation-<road>.json. From the repository's root:
#   bash docs/results/allroads-published-validation/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT"
for s in 0 1 2; do
  for road in straight merge curve roundabout; do
    for lane in random non-target; do
      laneshift eval --checkpoint results/checkpoints/allroads-dqfd-bc-alongside-gaps-safe-shield-seed$s-final.safetensors \
        --scenario allroads --set env.road=$road --episodes 200 --seed 200000 --max-steps 300 \
        --initial-lane $lane --json > "$OUT/ar-base-s$s-$road-$lane.json"
    done
  done
done
