#!/bin/bash
# The behaviour-cloning diagnostic of docs/RESULTS.md ("Pixels"): bc.py on four views of the same 260 scripted
# episodes (episode seeds 10,000+), then drive.py on 100 validation episodes each. Revision: see README.md.
# Pixel shards: those of the pixel probes (laneshift experiment protocol writes them under the run's demos/);
# the vector shard: laneshift demos generate --scenario straight --observation vector --reward-preset 5
#   --initial-lane random --episodes 260 --seed 10000 --out SHARDS/vector
# usage: bash run.sh SHARDS OUT   (SHARDS/{vector,fi4,fi4-c0.3,fi8} the shards' directories)
set -e
S=$1; O=$2; D=$(dirname "$0"); mkdir -p "$O"
run() {  # label, rows, env options
  python "$D/bc.py" "$S/$1" "$1" --updates 20000 --rows "$2" --save "$O/$1.pt" | tee -a "$O/bc.jsonl"
  python "$D/drive.py" "$O/$1.pt" "$3" --episodes 100 | tee -a "$O/drive.jsonl"
}
run vector "" '{}'
run fi4 22:78 '{"observation": "grayscale", "frame_interval": 4}'
run fi4-c0.3 22:78 '{"observation": "grayscale", "frame_interval": 4, "frame_centering": 0.3}'
run fi8 22:78 '{"observation": "grayscale", "frame_interval": 8}'
