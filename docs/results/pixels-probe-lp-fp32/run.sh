# The pixel recipe's three seeds (docs/RESULTS.md, "The paper's question", pixels): probe 18 in float32 with one
# torch thread in phase 1, from worktrees of revision 97e0f36 (seeds 2 and 0, /work/study-w27) and 129993a
# (seed 1 again, /work/study-w28); the settings are the method preset dqfd-bc-pixels since a4f0bae
# (tests/test_config.py holds the preset to seed 2's recorded config). From a clone of main, drop the cd and
# run it in the repository root; a seed whose json exists is skipped, an unfinished run continues. Seed 1's
# first run (revision 5399754, then 128dff4, over the 2-hour bound) is in first-seed1/ of the --out dir.
# The same runs by the preset's name (other json and file names):
#   laneshift experiment protocol --scenario straight --method dqfd-bc-pixels --seeds 0,1,2 --env-steps 150000 \
#     --final-validation-episodes 200 --publish results/checkpoints
cd /work/study-w28
.venv/bin/laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds ${SEEDS:-0,1,2} \
  --env-steps 150000 --road straight-pixels-fi8-rows-im120k-lp-fp32 --out /work/study-w25/runs/protocol/straight-pixels-fi8-rows-im120k-lp-fp32-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 --set learner.phase1_updates=120000 --set learner.phase1_td=false \
  --set learner.frozen_steps=150000 --set learner.frozen_layers=all-but-output \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=fp32 --set learner.phase1_threads=1 \
  --final-validation-episodes 200 --publish results/checkpoints-probe18
