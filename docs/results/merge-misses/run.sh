#!/bin/bash
# Merge's missed validation episodes from a non-target lane, episode by episode: the published
# dqfd-bc-alongside-gaps-safe-shield network of seed 0 and the scripted driver behind the same shield on the same
# 200 validation episodes (seeds from 200,000); summarise.py compares them (docs/RESULTS.md, "Merge behind the
# shield"). Ran 2026-11-28 at revision c931dea. Run from the repository root; writes here.
set -e
out=docs/results/merge-misses
laneshift eval --checkpoint results/checkpoints/merge-dqfd-bc-alongside-gaps-safe-shield-seed0-final.safetensors \
  --episodes 200 --initial-lane non-target --max-steps 300 --seed 200000 --episodes-out $out/seed0.jsonl
laneshift eval --driver scripted --scenario merge --set env.shield=true --set env.alongside_features=true \
  --set env.gap_features=true --episodes 200 --initial-lane non-target --max-steps 300 --seed 200000 \
  --episodes-out $out/driver.jsonl
python $out/summarise.py $out
