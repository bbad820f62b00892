#!/bin/bash
# The shield's figures (docs/RESULTS.md, "the shield's figures"), from a checkout at revision
# a21c27d or later:  bash docs/results/shield-figures/run.sh OUT_DIR
# 1. validation episodes (200 per setting, seeds from 200,000, 300 steps): the published merge
#    dqfd-bc-alongside-gaps-safe-shield networks at 3 m / 0.9 (the driver's), 2 m / 1.0 and 2 m / 0.9,
#    and the straight dqfd-bc-alongside-safe-shield networks at 3 m / 0.9 and 2 m / 1.0;
# 2. the figures chosen there by the rule fixed before (mean validation survival >= 97 % in both
#    settings, then the highest mean validation achievement over both): 2 m / 1.0 on both roads, on
#    the test episodes (seeds from 100,000), with the drivers behind the same shield beside them;
# 3. the tables (summarise.py).
OUT=${1:?usage: run.sh OUT_DIR}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT/validation" "$OUT/test"
one() {  # one NET GAP DECEL EPISODE_SEED DIR
  for lane in random non-target; do
    f=$5/$1-gap$2-decel$3-$lane.json
    [ -s $f ] || laneshift eval --checkpoint results/checkpoints/$1-final.safetensors --episodes 200 --seed $4 \
       --max-steps 300 --initial-lane $lane --set env.shield_gap=$2 --set env.shield_decel=$3 --json > $f
  done
}
for s in 0 1 2; do
  for fig in "3.0 0.9" "2.0 1.0" "2.0 0.9"; do one merge-dqfd-bc-alongside-gaps-safe-shield-seed$s $fig 200000 $OUT/validation; done
  for fig in "3.0 0.9" "2.0 1.0"; do one straight-dqfd-bc-alongside-safe-shield-seed$s $fig 200000 $OUT/validation; done
  one merge-dqfd-bc-alongside-gaps-safe-shield-seed$s 2.0 1.0 100000 $OUT/test
  one straight-dqfd-bc-alongside-safe-shield-seed$s 2.0 1.0 100000 $OUT/test
done
python - "$OUT/test" <<'PY'
import sys
from pathlib import Path
from laneshift.config import EnvConfig
from laneshift.tools.studies.protocol_results import drive_baselines
for road in ("merge", "straight"):
    env = EnvConfig(scenario=road, max_steps=300, shield=True, shield_gap=2.0, shield_decel=1.0)
    drive_baselines(env, 200, Path(sys.argv[1]), f"baselines-{road}-gap2.0-decel1.0.json")
PY
python $HERE/summarise.py "$OUT"
