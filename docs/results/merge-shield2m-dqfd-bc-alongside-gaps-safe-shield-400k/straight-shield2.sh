#!/bin/bash
# Straight road, dqfd-bc-alongside-safe-shield trained behind the shield figures the test uses (2 m / 1.0)
cd /work/study-w10
.venv/bin/laneshift experiment protocol --scenario straight --method dqfd-bc-alongside-safe-shield --seeds 0,1,2 \
  --env-steps 600000 --road straight-shield2m --set env.shield=true --set env.shield_gap=2.0 --set env.shield_decel=1.0 \
  --out /work/runs/w10/protocol/straight-shield2m-dqfd-bc-alongside-safe-shield-600k --publish /work/runs/w10/publish
