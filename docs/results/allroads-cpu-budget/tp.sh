#!/bin/bash
# A B A B: the allroads recipe's learner pinned to one CPU with one torch thread (the default) against
# unpinned with two (deploy.learner_core=-1, learner.torch_threads=2); 200,000-step runs cut after 170 s,
# no greedy evaluation. Its phase-2 rates come from the progress lines (see README.md here).
#   bash tp.sh LANESHIFT CONFIG OUT_DIR     (CONFIG: allroads-heads-wide-bf16.yaml, its demo_paths set)
LS=${1:?laneshift command}; CFG=${2:?config}; OUT=${3:?out dir}; mkdir -p "$OUT"
tp() { # name extra-sets...
  local name=$1; shift
  $LS train --config "$CFG" --env-steps 200000 --set learner.phase1_updates=2000 --set train.eval_every=0 \
     --run-dir "$OUT/tp-$name" --overwrite "$@" > "$OUT/tp-$name.log" 2>&1 &
  local pid=$!; sleep 170; kill -INT $pid; wait $pid
}
tp pinned1-a
tp unpinned2-a --set deploy.learner_core=-1 --set learner.torch_threads=2
tp pinned1-b
tp unpinned2-b --set deploy.learner_core=-1 --set learner.torch_threads=2
