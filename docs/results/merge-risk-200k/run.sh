#!/bin/bash
# The merge risk ablation of docs/RESULTS.md: does the learner take the risky lane change because
# the objective pays for it? One seed (0), 200,000 env steps a run, dqfd-bc-alongside with one change
# each to what a crash costs (learner.terminal_value) or how far ahead the value looks
# (learner.gamma); the final network on 200 validation episodes per initial-lane setting (seeds from
# 200,000; never the test episodes). Run from a checkout at revision 7a2e90d or later:
#   bash docs/results/merge-risk-200k/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT"
run() {
  name=$1; steps=$2; shift 2
  if [ -f "$OUT/$name/val-non-target.json" ]; then return; fi
  laneshift train --method dqfd-bc-alongside --scenario merge --env-steps $steps --run-dir $OUT/$name --overwrite \
     --run-id r$name --set env.max_steps=300 --set train.seed=0 --set actor.seed=0 --set learner.seed=0 \
     --set replay.seed=0 --set train.eval_episodes=0 --set train.eval_every=50000 \
     --set train.periodic_eval_episodes=20 --set train.validation_seed=200000 "$@" > $OUT/$name.log 2>&1
  for lane in random non-target; do
    laneshift eval --checkpoint $OUT/$name/checkpoints/final.safetensors --episodes 200 --seed 200000 \
       --max-steps 300 --initial-lane $lane --set env.alongside_features=true --json > $OUT/$name/val-$lane.json
  done
}
run base 200000
run tv100 200000 --set learner.terminal_value=-100
run g995 200000 --set learner.gamma=0.995
run g995-tv200 200000 --set learner.gamma=0.995 --set learner.terminal_value=-200
run tv300 200000 --set learner.terminal_value=-300
run tv1000 200000 --set learner.terminal_value=-1000
