#!/bin/bash
# The published dqfd-bc-alongside-safe networks (trained without the shield) behind the safety shield
# at test time only (docs/RESULTS.md, "behind a safety shield"): 200 test episodes per initial-lane
# setting (seeds from 100,000, 300 steps), the same commands the networks' JSONs name plus
# --set env.shield=true; then the table with 95 % bootstrap intervals over the three seeds.
# Run from a checkout at revision d7f3b45 or later:  bash docs/results/shield-at-test/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT"
for road in straight merge curve roundabout; do for s in 0 1 2; do for lane in random non-target; do
  f=$OUT/$road-s$s-$lane.json
  [ -s $f ] || laneshift eval --checkpoint results/checkpoints/$road-dqfd-bc-alongside-safe-seed$s-final.safetensors \
     --episodes 200 --seed 100000 --max-steps 300 --initial-lane $lane --set env.shield=true --json | tail -1 > $f
done; done; done
# merge's dqfd-bc-alongside networks too (chosen on validation episodes: 1.5-3 points more achievement
# behind the shield than dqfd-bc-alongside-safe's; docs/results/shield-probes/)
for s in 0 1 2; do for lane in random non-target; do
  f=$OUT/merge-alongside-s$s-$lane.json
  [ -s $f ] || laneshift eval --checkpoint results/checkpoints/merge-dqfd-bc-alongside-seed$s-final.safetensors \
     --episodes 200 --seed 100000 --max-steps 300 --initial-lane $lane --set env.shield=true \
     --set env.alongside_features=true --json | tail -1 > $f
done; done
# the allroads networks (one network for the four roads), each road's own test episodes
for road in straight merge curve roundabout; do for s in 0 1 2; do for lane in random non-target; do
  f=$OUT/allroads-$road-s$s-$lane.json
  [ -s $f ] || laneshift eval --checkpoint results/checkpoints/allroads-dqfd-bc-alongside-safe-seed$s-final.safetensors \
     --scenario allroads --episodes 200 --seed 100000 --max-steps 300 --initial-lane $lane --set env.shield=true \
     --set env.alongside_features=true --set env.road=$road --json | tail -1 > $f
done; done; done
python $HERE/summarise.py $OUT > $OUT/table.md && cat $OUT/table.md
