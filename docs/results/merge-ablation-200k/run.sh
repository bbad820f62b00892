#!/bin/bash
# The merge ablation of docs/RESULTS.md: one seed (0), 200,000 env steps a run, dqfd-bc-anneal with one
# change each, the final network on 200 validation episodes per initial-lane setting (seeds from
# 200,000; never the test episodes). Run from a checkout at revision 4cca58b or later:
#   bash docs/results/merge-ablation-200k/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
run() {
  name=$1; steps=$2; shift 2
  laneshift train --method dqfd-bc-anneal --scenario merge --env-steps $steps --run-dir $OUT/$name --overwrite \
     --run-id g$name --set env.max_steps=300 --set train.seed=0 --set actor.seed=0 --set learner.seed=0 \
     --set replay.seed=0 --set train.eval_episodes=0 --set train.eval_every=50000 \
     --set train.periodic_eval_episodes=20 --set train.validation_seed=200000 "$@" > $OUT/$name.log 2>&1
  env_set=$(printf '%s\n' "$@" | grep '^env\.' | grep -v '^env.initial_lane' | sed 's/^/--set /' | tr '\n' ' ')
  for lane in random non-target; do
    laneshift eval --checkpoint $OUT/$name/checkpoints/final.safetensors --episodes 200 --seed 200000 \
       --max-steps 300 --initial-lane $lane $env_set --json > $OUT/$name/val-$lane.json
  done
}
run base 200000
run pretrain-only 2000
run bc5 200000 --set learner.bc_loss_weight=5
run per 200000 --set replay.sampler=prioritized
run per-bc5 200000 --set replay.sampler=prioritized --set learner.bc_loss_weight=5
run demos1000 200000 --set train.demo_episodes=1000 --set replay.capacity=590000 --set replay.demo_ratio=0.5
run h512 200000 --set learner.hidden=512,512
run tup2000 200000 --set learner.target_update_period=2000
run lr2e4 200000 --set learner.lr=2e-4 --set learner.lr_final=2e-5
run spi64 200000 --set replay.samples_per_insert=64
run nontarget 200000 --set env.initial_lane=non-target
run alongside 200000 --set env.alongside_features=true
run alongside-per 200000 --set env.alongside_features=true --set replay.sampler=prioritized
