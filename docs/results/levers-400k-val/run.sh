#!/bin/bash
# The lever ablation of docs/RESULTS.md ("Merge and roundabout: what did not move them"): prioritized
# replay, 20-step returns and 1,000 demonstration episodes on dqfd-bc-alongside-safe, merge and roundabout, one seed (0), 400,000 env
# steps a run; the final network on 200 validation episodes per initial-lane setting (seeds from
# 200,000; never the test episodes). The bases are seed 0's final networks of the 400,000-step
# protocol rows (results/checkpoints/{merge,roundabout}-dqfd-bc-alongside-safe-seed0-final.safetensors,
# revision e32212f). Run from a checkout at revision d1a6e8a or later:
#   bash docs/results/levers-400k-val/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT"
evalv() {  # evalv CHECKPOINT DIR: the validation episodes, both settings
  for lane in random non-target; do
    [ -f "$2/val-$lane.json" ] || laneshift eval --checkpoint $1 --episodes 200 --seed 200000 \
       --max-steps 300 --initial-lane $lane --json > $2/val-$lane.json
  done
}
val() {  # val ROAD NAME [--set ...]
  road=$1; name=$2; shift 2
  [ -f "$OUT/$name/val-non-target.json" ] && return
  laneshift train --method dqfd-bc-alongside-safe --scenario $road --env-steps 400000 --run-dir $OUT/$name --overwrite \
     --run-id r$name --set env.max_steps=300 --set train.seed=0 --set actor.seed=0 --set learner.seed=0 \
     --set replay.seed=0 --set train.eval_episodes=0 --set train.eval_every=100000 \
     --set train.periodic_eval_episodes=20 --set train.validation_seed=200000 "$@" > $OUT/$name.log 2>&1
  evalv $OUT/$name/checkpoints/final.safetensors $OUT/$name
}
mkdir -p $OUT/roundabout-base400k
evalv results/checkpoints/roundabout-dqfd-bc-alongside-safe-seed0-final.safetensors $OUT/roundabout-base400k
val merge merge-per400k --set replay.sampler=prioritized
val merge merge-n20-400k --set learner.n_step=20
val roundabout roundabout-per400k --set replay.sampler=prioritized
val roundabout roundabout-n20-400k --set learner.n_step=20
val merge merge-demos1000-400k --set train.demo_episodes=1000 --set replay.capacity=590000 --set replay.demo_ratio=0.5
val roundabout roundabout-demos1000-400k --set train.demo_episodes=1000 --set replay.capacity=586000 --set replay.demo_ratio=0.5
