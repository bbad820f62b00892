#!/bin/bash
# Validation probes of docs/RESULTS.md, "where the gap is" (200 validation episodes per initial-lane
# setting, seeds from 200,000, 300 steps; never the test episodes), from a checkout at revision
# 548a093 or later:  bash docs/results/gap-features/run.sh OUT_DIR
# 1. the published dqfd-bc-alongside-safe-shield networks of seed 0 (merge, straight, curve) -> base-*;
# 2. the same method with env.gap_features=true, seed 0, trained as the protocol trains -> *-gaps-*.
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT"
evalv() {  # evalv CHECKPOINT NAME
  for lane in random non-target; do
    [ -s "$OUT/$2-$lane.json" ] || laneshift eval --checkpoint $1 --episodes 200 --seed 200000 \
       --max-steps 300 --initial-lane $lane --json > "$OUT/$2-$lane.json"
  done
}
for road in merge straight curve; do
  evalv results/checkpoints/$road-dqfd-bc-alongside-safe-shield-seed0-final.safetensors base-$road-shield-s0
  steps=400000; [ $road = straight ] && steps=600000
  [ -f "$OUT/$road-gaps-shield-s0/checkpoints/final.safetensors" ] || \
  laneshift train --method dqfd-bc-alongside-safe-shield --scenario $road --env-steps $steps \
     --run-dir "$OUT/$road-gaps-shield-s0" --overwrite --run-id r$road-gaps --set env.max_steps=300 \
     --set train.seed=0 --set actor.seed=0 --set learner.seed=0 --set replay.seed=0 \
     --set train.eval_episodes=0 --set train.eval_every=100000 --set train.periodic_eval_episodes=20 \
     --set train.validation_seed=200000 --set env.gap_features=true
  evalv "$OUT/$road-gaps-shield-s0/checkpoints/final.safetensors" $road-gaps-shield-s0
done
