#!/bin/bash
# Roll-in demonstrations on merge (DAgger's idea; docs/RESULTS.md, "behind a safety shield"): seed 0's
# published dqfd-bc-alongside-safe network drives the first 0-150 steps of 300 training-range episodes
# (seeds from 30,000), the scripted driver the rest, and only the driver's part is recorded; a run of
# dqfd-bc-alongside-safe then trains on that shard beside the protocol's own (seed 0, 400,000 env
# steps), tested on 200 validation episodes per initial-lane setting (seeds from 200,000). Measured at
# revision d1a6e8a; run from a checkout at d7f3b45 or later:
#   bash docs/results/merge-rollin-val/run.sh OUT_DIR DEMO_SHARD
# DEMO_SHARD: the protocol's scripted merge shard (runs/protocol/merge-dqfd-bc-alongside-safe-400k/demos/...-390ep).
OUT=${1:?usage: run.sh OUT_DIR DEMO_SHARD}; ORIG=${2:?usage: run.sh OUT_DIR DEMO_SHARD}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT"
[ -d $OUT/merge-rollin-s0-300ep ] || python $HERE/rollin_shard.py \
   results/checkpoints/merge-dqfd-bc-alongside-safe-seed0-final.safetensors $OUT/merge-rollin-s0-300ep 300 30000
name=merge-rollin300
laneshift train --method dqfd-bc-alongside-safe --scenario merge --env-steps 400000 --run-dir $OUT/$name --overwrite \
   --run-id r$name --set env.max_steps=300 --set train.seed=0 --set actor.seed=0 --set learner.seed=0 \
   --set replay.seed=0 --set train.eval_episodes=0 --set train.eval_every=100000 \
   --set train.periodic_eval_episodes=20 --set train.validation_seed=200000 \
   --set "replay.demo_paths=[$ORIG,$OUT/merge-rollin-s0-300ep]" > $OUT/$name.log 2>&1
for lane in random non-target; do
  laneshift eval --checkpoint $OUT/$name/checkpoints/final.safetensors --episodes 200 --seed 200000 \
     --max-steps 300 --initial-lane $lane --json | tail -1 > $OUT/$name/val-$lane.json
done
