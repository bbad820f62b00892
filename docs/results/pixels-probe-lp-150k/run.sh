# Probe 18, run from a frozen worktree of revision 5399754 at /work/study-w25 (its paths below);
# from a clone of main, drop the cd and run it in the repository root. Seeds 1 and 2: --seeds 0,1,2 (seed 0 is skipped when its json exists).
# The protocol resumes an unfinished run with the same command.
# On a CPU without bfloat16 instructions (the learner's first lines say so) bf16 is emulated, ten times
# slower: add --set learner.cnn_precision=fp32 --set learner.phase1_threads=1 (docs/RESULTS.md, "On a slower machine").
cd /work/study-w25
.venv/bin/laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds 0 \
  --env-steps 150000 --road straight-pixels-fi8-rows-im120k-lp --out runs/protocol/straight-pixels-fi8-rows-im120k-lp-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 --set learner.phase1_updates=120000 --set learner.phase1_td=false \
  --set learner.frozen_steps=150000 --set learner.frozen_layers=all-but-output \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=bf16 \
  --final-validation-episodes 200
