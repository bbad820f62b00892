#!/bin/bash
# Which test episodes the straight road's networks miss from a non-target lane, and whether the
# scripted driver misses the same ones (docs/RESULTS.md, "Straight road: the episodes that are
# missed"). Not a choice of anything: the published networks and the driver, on the protocol's test
# episodes (seeds from 100,000, 200 episodes, 300 steps), behind the shield at the figures the
# networks were trained with (3 m / 0.9) and at the ones chosen on validation episodes (2 m / 1.0).
#   bash docs/results/straight-misses/run.sh OUT_DIR      (from the repository's root)
OUT=${1:?usage: run.sh OUT_DIR}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT"
for fig in "3.0 0.9" "2.0 1.0"; do
  set -- $fig
  tag=gap$1-decel$2
  common="--episodes 200 --seed 100000 --max-steps 300 --initial-lane non-target --json"
  for s in 0 1 2; do
    f=$OUT/seed$s-$tag
    [ -s $f.jsonl ] || laneshift eval --checkpoint results/checkpoints/straight-dqfd-bc-alongside-safe-shield-seed$s-final.safetensors \
      $common --set env.shield_gap=$1 --set env.shield_decel=$2 --episodes-out $f.jsonl > $f.json
  done
  f=$OUT/driver-$tag
  [ -s $f.jsonl ] || laneshift eval --driver scripted --scenario straight $common --set env.shield=true \
    --set env.shield_gap=$1 --set env.shield_decel=$2 --episodes-out $f.jsonl > $f.json
done
python "$HERE/summarise.py" "$OUT"
