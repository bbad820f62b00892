#!/bin/bash
# Merge, dqfd-bc-alongside-gaps-safe-shield trained behind the shield figures the test uses (2 m / 1.0);
# starts once the straight study has ended (one run at a time).
while pgrep -f straight-shield2.sh > /dev/null; do sleep 10; done
cd /work/study-w10
.venv/bin/laneshift experiment protocol --scenario merge --method dqfd-bc-alongside-gaps-safe-shield --seeds 0,1,2 \
  --env-steps 400000 --set env.max_steps=300 --road merge-shield2m --set env.shield=true --set env.shield_gap=2.0 \
  --set env.shield_decel=1.0 --out /work/runs/w10/protocol/merge-shield2m-dqfd-bc-alongside-gaps-safe-shield-400k \
  --publish /work/runs/w10/publish
