#!/bin/bash
# Real-run phase-1 A/B: each arm a laneshift train run of the probe-14 recipe, stopped after 170 s; updates/s from
# its metrics between 70 s and the end. Arms: torch2 = revision 8029542 (torch crops), 2 phase-1 threads;
# numpy2 = revision fe4a4bb (numpy crops), 2 threads; numpy1 = fe4a4bb with learner.phase1_threads=1.
# WT: this machine's frozen checkouts at those revisions, each with its own venv; SHARD: probe 14's demo shard.
SHARD=/work/study-w21/runs/protocol/straight-pixels-fi8-rows-spi32-pre60k-150k/demos/straight-grayscale4x100x100-fi8-p5-scripted-v2-260ep
SETS="--set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 --set learner.cnn_rows=22:78
 --set learner.phase1_updates=60000 --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4
 --set learner.lr_final=1e-5 --set learner.augment=shift --set learner.cnn_precision=bf16"
for i in 1 2; do
  for arm in torch2 numpy2 numpy1; do
    case $arm in
      torch2) WT=/work/study-w21; EXTRA="";;
      numpy2) WT=/work/study-w22; EXTRA="";;
      numpy1) WT=/work/study-w22; EXTRA="--set learner.phase1_threads=1";;
    esac
    RD=/work/runs/p1ab/$arm-$i
    cd $WT
    .venv/bin/laneshift train --method dqfd-bc-anneal --scenario straight --observation grayscale --env-steps 150000 \
      --demos $SHARD --run-dir $RD --overwrite $SETS $EXTRA > /work/runs/p1ab/$arm-$i.log 2>&1 &
    PID=$!
    sleep 170
    kill -TERM $PID; wait $PID
    python3 - "$RD" "$arm" "$i" <<'PY'
import json, sys
rs = [json.loads(l) for l in open(sys.argv[1] + "/metrics.jsonl")]
L = [r for r in rs if r.get("kind") == "learner" and r.get("phase") == 1 and r["elapsed_s"] >= 70]
a, b = L[0], L[-1]
print(json.dumps({"arm": sys.argv[2], "round": int(sys.argv[3]), "from_s": a["elapsed_s"], "to_s": b["elapsed_s"],
                  "updates_per_s": round((b["updates"] - a["updates"]) / (b["elapsed_s"] - a["elapsed_s"]), 1)}), flush=True)
PY
    sleep 5
  done
done
