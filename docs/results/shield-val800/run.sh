#!/bin/bash
# Issue 27: do the roads where the published networks beat the scripted driver on the 200 test episodes (behind the
# shield, the imitation losses fading to 0: straight, curve, roundabout, straight with 3 policy vehicles) beat it on
# 800 FRESH validation episodes too (episode seeds 200,200-200,999, 300 steps, used for no choice; the test episodes
# start at 100,000 and are not read here)? Merge's lead of 0.2 on the test episodes was a deficit of 1.8 on such
# episodes (docs/results/merge-val800/). Each network's command is its JSON's test command with the episodes moved;
# the driver drives the same episodes behind the same shield. Two evaluations at a time (the machine's 2 CPUs);
# the same command resumes. From the repository's root:
#   bash docs/results/shield-val800/run.sh OUT_DIR
#   python docs/results/shield-val800/summarise.py OUT_DIR > docs/results/shield-val800/table.md
OUT=${1:?usage: run.sh OUT_DIR}
LANESHIFT=${LANESHIFT:-laneshift}
ROADS=${ROADS:-straight-imfade curve-imfade roundabout-imfade straight-policytraffic-imfade}
mkdir -p "$OUT"
jobs=()
for road in $ROADS; do
  for lane in non-target random; do
    for s in 0 1 2; do
      json=results/checkpoints/$road-dqfd-bc-alongside-safe-shield-seed$s-final.json
      cmd=$(python3 -c "import json, sys; print(json.load(open(sys.argv[1]))['test']['lanes'][sys.argv[2]]['command'])" \
            "$json" "$lane")
      cmd=${cmd/--episodes 200 --seed 100000/--episodes 800 --seed 200200}
      jobs+=("$road-s$s|$lane|${cmd#laneshift eval }")
      if [ "$s" = 0 ]; then  # the driver: the same env options, no checkpoint
        jobs+=("$road-driver|$lane|--driver scripted $(sed -E 's/--checkpoint [^ ]+ //' <<< "${cmd#laneshift eval }")")
      fi
    done
  done
done
printf '%s\n' "${jobs[@]}" | xargs -P 2 -I{} bash -c '
  IFS="|" read -r name lane args <<< "{}"
  out="'"$OUT"'/$name-$lane.jsonl"
  [ -s "$out" ] && exit 0  # done by an earlier call
  if '"$LANESHIFT"' eval $args --episodes-out "$out.part" > /dev/null; then
    mv "$out.part" "$out" && echo "$name $lane done"
  else
    echo "$name $lane FAILED" >&2; exit 1
  fi'
