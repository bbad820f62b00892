"""Merge, the 10 validation episodes from a non-target lane that neither a published merge-pre60k network nor
the scripted driver solves (docs/results/merge-oracle/episodes.jsonl, solved there by the search only): how many
the held-exploration networks solve. Run from the repository root after run.sh::

    python docs/results/merge-pre60k-hold-400k/hard10.py RUN_ROOT

Room: a study's script beside its results (run by path, not installed). May import: laneshift, numpy.
"""
import json
import sys

sys.path.insert(0, "docs/results/merge-oracle")
from oracle import ENV, drive, load_greedy_policy, make  # noqa: E402

root = sys.argv[1]  # the protocol's --out
rows = [json.loads(line) for line in open("docs/results/merge-oracle/episodes.jsonl")]
hard = [r["seed"] for r in rows if r["search"]]
env = make(ENV)
u = env.unwrapped
for s in (1, 2, 0):
    net = load_greedy_policy(f"{root}/dqfd-bc-alongside-gaps-safe-shield-s{s}/checkpoints/final.safetensors")
    got = []
    for seed in hard:
        obs, _ = env.reset(seed=seed)
        got.append(drive(u, net, obs)["achieved"])
    print(f"seed {s} (held exploration): solves {sum(got)} of the {len(hard)} episodes no published network "
          f"nor the driver solved ({[sd for sd, ok in zip(hard, got) if ok]})")
