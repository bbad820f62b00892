#!/bin/bash
# CPU accounting of the allroads recipe in phase 2: CPU-seconds of the learner process per update and of
# every other process of the run (workers, replay server, router, Ray's own, the launcher) per env step,
# over 60 s, for replay.samples_per_insert 32 (the recipe) and 16, A B A B. Lines go to OUT_DIR/acct.txt.
#   bash acct.sh LANESHIFT CONFIG OUT_DIR
LS=${1:?laneshift command}; CFG=${2:?config}; W=${3:?out dir}; mkdir -p "$W"
desc() { local p=$1; echo $p; for c in $(cat /proc/$p/task/*/children 2>/dev/null); do desc $c; done; }
snap() { # launcher pid -> "learner_ticks other_ticks"
  local l=0 o=0
  for p in $(desc $1); do
    t=$(awk '{print $14+$15}' /proc/$p/stat 2>/dev/null) || continue
    if grep -q LearnerActor /proc/$p/cmdline 2>/dev/null; then l=$((l+t)); else o=$((o+t)); fi
  done; echo "$l $o"; }
last() { grep "phase 2" $1 | tail -1 | sed -E 's/.*steps +([0-9,]+)\/.*upd +([0-9,]+) .*/\1 \2/; s/,//g'; }
acct() { # name extra-sets...
  local name=$1; shift
  $LS train --config "$CFG" --env-steps 300000 --set learner.phase1_updates=2000 --set train.eval_every=0 \
     --run-dir "$W/acct-$name" --overwrite "$@" > "$W/acct-$name.log" 2>&1 &
  local pid=$!; sleep 80
  read l1 o1 < <(snap $pid); read s1 u1 < <(last "$W/acct-$name.log"); sleep 60
  read l2 o2 < <(snap $pid); read s2 u2 < <(last "$W/acct-$name.log")
  kill -INT $pid; wait $pid
  python3 -c "
l,o,s,u=($l2-$l1)/100,($o2-$o1)/100,$s2-$s1,$u2-$u1
print(f'$name: {s} env steps, {u} updates in 60 s; learner {l:.1f} CPU-s ({u/l:.1f} upd per CPU-s), '
      f'the rest {o:.1f} CPU-s ({o/s*1e3:.2f} ms per env step, {s/o:.0f} env steps per CPU-s)')" >> "$W/acct.txt"
}
acct spi32
acct spi16 --set replay.samples_per_insert=16
acct spi32-b
acct spi16-b --set replay.samples_per_insert=16
