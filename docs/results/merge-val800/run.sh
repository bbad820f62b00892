#!/bin/bash
# Issue 27: is the holding's lift on merge real? The published merge networks with and without the holding
# (merge-pre60k-hold and merge-pre60k: dqfd-bc-alongside-gaps-safe-shield, 60,000 pre-training updates, 400,000 env
# steps, seeds 0-2; results/checkpoints/) and the scripted driver behind the same shield, on 800 FRESH validation
# episodes per initial-lane setting (episode seeds 200,200-200,999, 300 steps): never used for any choice before (the
# holding was chosen on 200,000-200,199, and the test episodes start at 100,000 and are not read here). Optional:
# the stopped probes' seed-1 networks (EXTRA="name=path ..."); ONLY_EXTRA=1 drives those alone. Two evaluations at
# a time (the machine's 2 CPUs).
# From the repository's root:
#   bash docs/results/merge-val800/run.sh OUT_DIR
#   python docs/results/merge-val800/summarise.py OUT_DIR > docs/results/merge-val800/table.md
OUT=${1:?usage: run.sh OUT_DIR}
LANESHIFT=${LANESHIFT:-laneshift}
mkdir -p "$OUT"
ENV="--scenario merge --episodes 800 --seed 200200 --max-steps 300 --set env.alongside_features=true \
--set env.gap_features=true --set env.shield=true"
jobs=()
for lane in non-target random; do
  [ -n "$ONLY_EXTRA" ] || jobs+=("driver|$lane|--driver scripted")
  for recipe in merge-pre60k-hold merge-pre60k; do
    [ -n "$ONLY_EXTRA" ] && break
    for s in 0 1 2; do
      ckpt=results/checkpoints/$recipe-dqfd-bc-alongside-gaps-safe-shield-seed$s-final.safetensors
      jobs+=("$recipe-s$s|$lane|--checkpoint $ckpt")
    done
  done
  for e in $EXTRA; do jobs+=("${e%%=*}|$lane|--checkpoint ${e#*=}"); done
done
printf '%s\n' "${jobs[@]}" | xargs -P 2 -I{} bash -c '
  IFS="|" read -r name lane who <<< "{}"
  out="'"$OUT"'/$name-$lane.jsonl"
  [ -s "$out" ] && exit 0  # done by an earlier call: the same command resumes
  if '"$LANESHIFT"' eval $who '"$ENV"' --initial-lane $lane --episodes-out "$out.part" > /dev/null; then
    mv "$out.part" "$out" && echo "$name $lane done"
  else
    echo "$name $lane FAILED" >&2; exit 1
  fi'
