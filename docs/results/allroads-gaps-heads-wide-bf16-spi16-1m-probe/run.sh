#!/bin/bash
# The allroads network that meets its target (one Q head per road, 512 x 512, behind the shield with
# the gap features) cut towards the 15-minute bound: hidden layers in bfloat16, half the replay ratio
# (replay.samples_per_insert=16) and half the pre-training (learner.phase1_updates=10000), seed 0, with
# the final network on the validation episodes: docs/RESULTS.md, "What does lift them". From the
# repository's root: bash docs/results/allroads-gaps-heads-wide-bf16-spi16-1m-probe/run.sh OUT_DIR
OUT=${1:?usage: run.sh OUT_DIR}
laneshift experiment protocol --scenario allroads --method dqfd-bc-alongside-gaps-safe-shield --seeds 0 \
    --env-steps 1000000 --set env.max_steps=300 --set learner.heads=4 --set learner.hidden=512,512 \
    --set learner.mlp_precision=bf16 --set replay.samples_per_insert=16 --set learner.phase1_updates=10000 \
    --road allroads-heads-wide-bf16-spi16 --final-validation-episodes 200 --out "$OUT"
