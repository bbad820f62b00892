# Probe 18 in float32 (docs/RESULTS.md, pixels, "On a slower machine"): probe 18's command with
# --set learner.cnn_precision=fp32, for a CPU without bfloat16 instructions. Seed 1 pre-trained at
# revision 5399754 (/work/study-w25), was stopped and resumed (`--resume` by the protocol: the same
# command continues an unfinished run) and finished at revision 128dff4 (/work/study-w26, the command
# below); from a clone of main, drop the cd and run it in the repository root. Seeds 0 and 2: --seeds 0,1,2
# (a seed whose json exists is skipped); add --set learner.phase1_threads=0 (the default) from revision 97e0f36,
# where phase 1 asks the replay for no next observations.
cd /work/study-w26
.venv/bin/laneshift experiment protocol --scenario straight --method dqfd-bc-anneal --seeds ${SEEDS:-1} \
  --env-steps 150000 --road straight-pixels-fi8-rows-im120k-lp-fp32 --out /work/study-w25/runs/protocol/straight-pixels-fi8-rows-im120k-lp-fp32-150k \
  --set env.observation=grayscale --set env.frame_interval=8 --set learner.cnn=small --set learner.batch_size=32 \
  --set learner.cnn_rows=22:78 --set learner.phase1_updates=120000 --set learner.phase1_td=false \
  --set learner.frozen_steps=150000 --set learner.frozen_layers=all-but-output \
  --set replay.samples_per_insert=32 --set replay.capacity=200000 --set learner.lr=1e-4 --set learner.lr_final=1e-5 \
  --set learner.augment=shift --set learner.cnn_precision=fp32 \
  --final-validation-episodes 200 --publish results/checkpoints-probe18
