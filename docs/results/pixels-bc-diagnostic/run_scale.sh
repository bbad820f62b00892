#!/bin/bash
# The behaviour-cloning diagnostic's longer run (README.md, the last two rows): bc.py on the shard of frames 8 steps
# apart for up to 160,000 updates, the network saved at 40,000, 80,000 and 120,000, then drive.py on the validation
# episodes (100 from a random lane at 80,000 and 120,000; 200 per setting at 120,000). The run in README.md was
# stopped at 132,000 updates, so its 160,000-update network was never saved or driven.
# usage: bash run_scale.sh SHARDS OUT   (SHARDS/fi8 the shard's directory; laneshift's venv on PATH)
set -e
S=$1; O=$2; D=$(dirname "$0"); mkdir -p "$O"
python "$D/bc.py" "$S/fi8" fi8-160k --updates 160000 --rows 22:78 --save "$O/fi8.pt" --save-at 40000,80000,120000 \
  | tee -a "$O/bc.jsonl"
view='"observation": "grayscale", "frame_interval": 8'
for u in 80000 120000; do
  python "$D/drive.py" "$O/fi8-$u.pt" "{$view}" --episodes 100 | tee -a "$O/drive.jsonl"
done
for lane in random non-target; do
  python "$D/drive.py" "$O/fi8-120000.pt" "{$view, \"initial_lane\": \"$lane\"}" --episodes 200 | tee -a "$O/drive200.jsonl"
done
