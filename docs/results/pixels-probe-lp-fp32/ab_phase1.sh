# Phase 1's updates/s in the run itself, A B A B: probe 18's pre-training (imitation alone) from a run's
# config, 6,000 updates each, then the median of the learner's 1-second reports past 1,000 updates.
#   bash ab_phase1.sh RUN_CONFIG LABEL:WORKTREE:PHASE1_THREADS ...
# e.g. (docs/RESULTS.md, "On a slower machine"): seed 1's config.yaml, new0:/work/study-w27:0
# new1:/work/study-w27:1 old1:/work/study-w26:1, twice over (revision 97e0f36 against 128dff4).
CFG=$1; shift
for spec in "$@"; do
  IFS=: read label tree threads <<< "$spec"
  port=$(python3 -c "import socket;s=socket.socket();s.bind(('127.0.0.1',0));print(s.getsockname()[1])")
  dir=${AB_DIR:-/tmp}/ab1-$label-$(date +%H%M%S)
  (cd "$tree" && .venv/bin/laneshift train --config "$CFG" --run-dir "$dir" --run-id ab1 --overwrite \
     --set transport.router=tcp/127.0.0.1:$port --set learner.phase1_updates=6000 --set train.env_steps=64 \
     --set train.eval_every=0 --set learner.phase1_threads="$threads" > "$dir.log" 2>&1)
  python3 - "$dir" "$label" <<'PY'
import json, statistics, sys
rows = [json.loads(line) for line in open(sys.argv[1] + "/metrics.jsonl")]
ph1 = [r for r in rows if r.get("kind") == "learner" and r.get("phase") == 1 and r.get("updates", 0) > 1000]
v = [r["updates_per_s"] for r in ph1]
print(sys.argv[2], "phase-1 updates/s median", statistics.median(v), "mean", round(statistics.mean(v), 1),
      "n", len(v), "updates", ph1[-1]["updates"] if ph1 else None, flush=True)
PY
done
