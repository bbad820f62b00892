#!/bin/bash
# Validation episodes (200 per setting, seeds from 200,000, 300 steps) of each published network of
# this round, for the same choosing rule as docs/results/shield-figures (pick.py).
# Usage: bash validate.sh PUBLISH_DIR ROAD_METHOD OUT_DIR
pub=$1; name=$2; out=$3; mkdir -p $out
for s in 0 1 2; do
  for lane in random non-target; do
    f=$out/$name-seed$s-$lane.json
    [ -s $f ] || /work/study-w10/.venv/bin/laneshift eval --checkpoint $pub/$name-seed$s-final.safetensors \
      --episodes 200 --seed 200000 --max-steps 300 --initial-lane $lane --json > $f
  done
done
