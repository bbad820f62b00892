#!/bin/bash
# Issue 27, merge from a non-target lane: how well can a network that sees what merge's networks see copy the
# scripted driver at all? On 800 fresh validation episodes (docs/results/merge-val800/) the published networks are
# 2.6 points below the driver from a non-target lane (90.9 against 93.5) and 1.8 from a random lane, and eight
# levers on the learner did not close it. Three networks of seed 1, each the END OF PRE-TRAINING (phase 1, the
# network phase 2 starts from: checkpoints/phase1.safetensors), with the merge recipe's env and network
# (dqfd-bc-alongside-gaps-safe-shield, env.max_steps=300, 60,000 pre-training updates):
#   A  the recipe's own pre-training (TD + margin + cross-entropy on the default 390-episode driver shard)
#   B  the imitation losses alone (learner.phase1_td=false) on the same shard: a copy of the driver
#   C  the imitation losses alone on a shard five times larger (2,000 driver episodes; 74 % of an 800,000-item
#      buffer holds its 595,594 transitions)
# then the same 800 validation episodes per setting as merge-val800 (seeds 200,200-200,999; the test episodes are
# not driven), paired with the driver's and the published networks' outcomes there. A measurement, not a choice:
# if B or C copies the driver, a network of this observation can reach it and what loses the points is phase 2;
# if not, the copy is the bound. A recipe that comes of it is judged on other validation episodes (1,000 per
# setting from seed 201,000), never on these or on the test's.
# From the worktree of the revision named in the results (a clone's root works the same):
#   bash docs/results/merge-imitation-ceiling/run.sh RUNS_DIR EVAL_DIR
set -e
RUNS=${1:?usage: run.sh RUNS_DIR EVAL_DIR}
EVAL=${2:?usage: run.sh RUNS_DIR EVAL_DIR}
LANESHIFT=${LANESHIFT:-laneshift}
COMMON="--scenario merge --method dqfd-bc-alongside-gaps-safe-shield --env-steps 2000 --set env.max_steps=300 \
--set learner.phase1_updates=60000 --set train.seed=1"
train() {  # name, extra settings; a finished run is skipped, a stopped one resumed
  local dir=$RUNS/$1; shift
  # finished = ended by its budget (a run stopped by a signal also writes final.safetensors)
  grep -qs '"ended_by": "done"' "$dir/summary.json" && return 0
  if [ -e "$dir/config.yaml" ]; then
    $LANESHIFT train --resume "$dir" > "$dir.log" 2>&1
  else
    $LANESHIFT train $COMMON --run-dir "$dir" "$@" > "$dir.log" 2>&1
  fi
}
mkdir -p "$RUNS"
# A and C together: C's 2,000-episode shard is driven while A pre-trains; then B.
train A & a=$!
train C --set learner.phase1_td=false --set train.demo_episodes=2000 --set replay.capacity=800000 \
  --set replay.demo_ratio=0.74 & c=$!
wait $a; wait $c
train B --set learner.phase1_td=false
EXTRA="ceilA-s1=$RUNS/A/checkpoints/phase1.safetensors ceilB-s1=$RUNS/B/checkpoints/phase1.safetensors \
ceilC-s1=$RUNS/C/checkpoints/phase1.safetensors" ONLY_EXTRA=1 LANESHIFT=$LANESHIFT \
  bash docs/results/merge-val800/run.sh "$EVAL"
