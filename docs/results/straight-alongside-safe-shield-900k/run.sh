#!/bin/bash
# Straight road, dqfd-bc-alongside-safe-shield at 900,000 env steps (the published row: 600,000):
# does a longer budget move the non-target achievement? Ran from a checkout at revision b7ce204.
laneshift experiment protocol --scenario straight --method dqfd-bc-alongside-safe-shield --seeds 0,1,2 \
  --env-steps 900000 --road straight-900k \
  --out runs/protocol/straight-dqfd-bc-alongside-safe-shield-900k --publish runs/publish
