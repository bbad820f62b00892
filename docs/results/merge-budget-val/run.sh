#!/bin/bash
# The merge budget ablation of docs/RESULTS.md: does a longer run, or training episodes that all start
# in a non-target lane, close merge's gap? One seed (0), dqfd-bc-alongside-safe with one change each;
# the final network on 200 validation episodes per initial-lane setting (seeds from 200,000; never
# the test episodes). BASE_CHECKPOINT is the 400,000-step base: seed 0's final network of the
# protocol row in docs/results/merge-alongside-safe-400k/ (revision e32212f).
# Run from a checkout at revision d1a6e8a or later:
#   bash docs/results/merge-budget-val/run.sh OUT_DIR BASE_CHECKPOINT
OUT=${1:?usage: run.sh OUT_DIR BASE_CHECKPOINT}
BASE=${2:?usage: run.sh OUT_DIR BASE_CHECKPOINT}
mkdir -p "$OUT"
evalv() {  # evalv CHECKPOINT DIR: the validation episodes, both settings
  for lane in random non-target; do
    [ -f "$2/val-$lane.json" ] || laneshift eval --checkpoint $1 --episodes 200 --seed 200000 \
       --max-steps 300 --initial-lane $lane --set env.alongside_features=true --json > $2/val-$lane.json
  done
}
run() {
  name=$1; steps=$2; shift 2
  if [ -f "$OUT/$name/val-non-target.json" ]; then return; fi
  laneshift train --method dqfd-bc-alongside-safe --scenario merge --env-steps $steps --run-dir $OUT/$name --overwrite \
     --run-id r$name --set env.max_steps=300 --set train.seed=0 --set actor.seed=0 --set learner.seed=0 \
     --set replay.seed=0 --set train.eval_episodes=0 --set train.eval_every=100000 \
     --set train.periodic_eval_episodes=20 --set train.validation_seed=200000 "$@" > $OUT/$name.log 2>&1
  evalv $OUT/$name/checkpoints/final.safetensors $OUT/$name
}
mkdir -p $OUT/base400k && evalv $BASE $OUT/base400k
run s1m 1000000
run nt400k 400000 --set env.initial_lane=non-target
