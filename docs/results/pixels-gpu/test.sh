#!/bin/bash
# Test each seed's final network (from run_gpu.py) on the protocol's test episodes, here on the CPU:
# 200 greedy episodes per initial lane, episode seeds 100,000-100,199 (never used for any choice),
# 300 steps each. Usage: bash test.sh DIR (the folder holding seed<N>.safetensors); writes
# DIR/test-seed<N>-<lane>.json.
dir=${1:?usage: bash test.sh DIR}
for net in "$dir"/seed*.safetensors; do
  seed=$(basename "$net" .safetensors)
  for lane in random non-target; do
    laneshift eval --checkpoint "$net" --episodes 200 --seed 100000 --max-steps 300 --initial-lane $lane \
      --json > "$dir/test-$seed-$lane.json" &
  done
  wait
done
