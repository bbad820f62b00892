#!/bin/bash
# Validation probes of docs/RESULTS.md, "behind a safety shield" (200 validation episodes per
# initial-lane setting, seeds from 200,000, 300 steps; never the test episodes). Run from a checkout
# at revision d7f3b45 or later:  bash docs/results/shield-probes/run.sh OUT_DIR [SHIELD_PROTOCOL_DIR...]
# 1. the published dqfd-bc-alongside-safe networks with and without the shield at test
#    (-> shield-on-published-validation.json);
# 2. merge: the three seeds' networks as one, greedy on their mean Q (-> ensemble-merge-mean-validation.json);
# 3. each SHIELD_PROTOCOL_DIR (an `experiment protocol --method dqfd-bc-alongside-safe-shield` --out):
#    its networks behind the shield and alone (-> shield-trained-validation.json).
OUT=${1:?usage: run.sh OUT_DIR [SHIELD_PROTOCOL_DIR...]}; shift
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT"
val() {  # val CHECKPOINT NAME
  for sh in true false; do for lane in random non-target; do
    f=$OUT/$2-shield$sh-$lane.json
    [ -s $f ] || laneshift eval --checkpoint $1 --episodes 200 --seed 200000 --max-steps 300 \
       --initial-lane $lane --set env.shield=$sh --json | tail -1 > $f
  done; done
}
for road in merge roundabout curve straight; do for s in 0 1 2; do
  val results/checkpoints/$road-dqfd-bc-alongside-safe-seed$s-final.safetensors $road-s$s
done; done
python $HERE/ensemble_probe.py merge mean $OUT/ensemble-merge-mean.json \
  results/checkpoints/merge-dqfd-bc-alongside-safe-seed{0,1,2}-final.safetensors
for dir in "$@"; do for s in 0 1 2; do
  road=$(basename $dir | cut -d- -f1)
  val $dir/dqfd-bc-alongside-safe-shield-s$s/checkpoints/final.safetensors new-$road-s$s
done; done
