#!/bin/bash
# Merge with a 512 x 512 network (docs/RESULTS.md, "Merge behind the shield: where the gap is"), on
# the VALIDATION episodes (seeds 200,000-200,199, 300 steps, 200 per initial-lane setting); from the
# repository's root at revision 7c9b1bf or later:  bash docs/results/merge-gaps-wide-400k-probe/run.sh OUT_DIR
# 1. the published 256 x 256 networks (dqfd-bc-alongside-gaps-safe-shield, seeds 0-2) -> validation-published/;
# 2. the same method with learner.hidden=512,512, seed 0, trained and validated by the protocol.
OUT=${1:?usage: run.sh OUT_DIR}
mkdir -p "$OUT/validation-published"
for s in 0 1 2; do for lane in random non-target; do
  laneshift eval --checkpoint results/checkpoints/merge-dqfd-bc-alongside-gaps-safe-shield-seed$s-final.safetensors \
    --episodes 200 --seed 200000 --max-steps 300 --initial-lane $lane --json > "$OUT/validation-published/merge-pub-s$s-$lane.json"
done; done
laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield --seeds 0 --env-steps 400000 \
  --set env.max_steps=300 --set learner.hidden=512,512 --road merge-wide --final-validation-episodes 200 --out "$OUT/protocol"
