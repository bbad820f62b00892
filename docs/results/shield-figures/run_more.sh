#!/bin/bash
# The shield's figures on the other roads' published networks trained behind the shield (curve,
# roundabout: dqfd-bc-alongside-safe-shield; the straight road with 3 policy vehicles, whose copies
# drive behind the same shield): validation at 3 m / 0.9 and 2 m / 1.0, the same rule as run.sh picks,
# and only a pick other than the default goes to the test episodes (with the drivers behind that
# shield). From a checkout at revision a21c27d or later:
#   bash docs/results/shield-figures/run_more.sh OUT_DIR
OUT=${1:?usage: run_more.sh OUT_DIR}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$OUT/validation" "$OUT/test"
one() {  # one NET GAP DECEL EPISODE_SEED DIR (a checkpoint does not record its policy vehicles: set here)
  traffic=(); [[ $1 == straight-policytraffic-* ]] && traffic=(--set env.policy_vehicles=3)
  for lane in random non-target; do
    f=$5/$1-gap$2-decel$3-$lane.json
    [ -s $f ] || laneshift eval --checkpoint results/checkpoints/$1-final.safetensors --episodes 200 --seed $4 \
       --max-steps 300 --initial-lane $lane --set env.shield_gap=$2 --set env.shield_decel=$3 "${traffic[@]}" --json > $f
  done
}
NETS="curve-dqfd-bc-alongside-safe-shield roundabout-dqfd-bc-alongside-safe-shield straight-policytraffic-dqfd-bc-alongside-safe-shield"
for net in $NETS; do for s in 0 1 2; do for fig in "3.0 0.9" "2.0 1.0"; do
  one $net-seed$s $fig 200000 $OUT/validation
done; done; done
for net in $NETS; do
  pick=$(python $HERE/pick.py "$OUT/validation" $net)
  echo "$net: $pick"
  [ "$pick" = "3.0 0.9" ] && continue
  for s in 0 1 2; do one $net-seed$s $pick 100000 $OUT/test; done
  road=${net%%-dqfd*}
  python - "$OUT/test" $road $pick <<'PY'
import sys
from pathlib import Path
from laneshift.config import EnvConfig
from laneshift.tools.studies.protocol_results import drive_baselines
out, road, gap, decel = Path(sys.argv[1]), sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
scenario, vehicles = ("straight", 3) if road == "straight-policytraffic" else (road, 0)
env = EnvConfig(scenario=scenario, max_steps=300, shield=True, shield_gap=gap, shield_decel=decel, policy_vehicles=vehicles)
drive_baselines(env, 200, out, f"baselines-{road}-gap{gap}-decel{decel}.json")
PY
done
