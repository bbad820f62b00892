#!/bin/bash
# The greedy evaluation during training on the learner's CPU (revision A: 0adeeb4) against off it (B: 0adeeb4
# with baef67a, learner.cpus.beside_the_learner), A B A B: the allroads recipe with an evaluation of 20
# episodes every 20,000 env steps, 200,000-step runs cut after 200 s. Compare with rates.py OUT_DIR/tpe-*.log
# and each run's eval records (metrics.jsonl, kind "eval": eval_s).
#   bash tpe.sh LANESHIFT_A LANESHIFT_B CONFIG OUT_DIR
A=${1:?laneshift of revision A}; B=${2:?laneshift of revision B}; CFG=${3:?config}; OUT=${4:?out dir}
mkdir -p "$OUT"
tpe() { # name laneshift
  $2 train --config "$CFG" --env-steps 200000 --set learner.phase1_updates=2000 --set train.eval_every=20000 \
     --set train.periodic_eval_episodes=20 --run-dir "$OUT/tpe-$1" --overwrite > "$OUT/tpe-$1.log" 2>&1 &
  local pid=$!; sleep 200; kill -INT $pid; wait $pid
}
tpe on-a "$A"
tpe off-a "$B"
tpe on-b "$A"
tpe off-b "$B"
