#!/bin/bash
# The replay server's ingest and sample latency before (2dc100b: the write-ahead log alone) and after
# (main: + duplicate and late-seq bookkeeping), alternating, write-ahead log on (the default).
for round in 1 2; do
  (cd /work/study-bwal && .venv/bin/laneshift bench replay --json --work-dir /work/benchresend > /work/runs/benchresend/before-$round.json 2> /work/runs/benchresend/before-$round.err)
  (cd /work/main && .venv/bin/laneshift bench replay --json --work-dir /work/benchresend > /work/runs/benchresend/after-$round.json 2> /work/runs/benchresend/after-$round.err)
done
