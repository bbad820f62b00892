"""Closed-loop greedy driving of a ``bc.py`` network on the straight road: validation episodes
(seeds 200,000+, never the test seeds 100,000+), a random initial lane, 300 steps; one JSON line
with survival and achievement.

    python drive.py net.pt '{"observation": "grayscale", "frame_interval": 4}' --episodes 100

Room: a study script (docs/results). May import: anything in laneshift, torch, numpy.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np
import torch

from laneshift.actors.evaluation import GreedyPolicy, evaluate_policy
from laneshift.config import EnvConfig
from laneshift.qnet import build_q_network


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("network")
    parser.add_argument("env_kwargs", help="the env's options (env.* fields) as JSON: the shard's view")
    parser.add_argument("--episodes", type=int, default=50)
    args = parser.parse_args()
    torch.set_num_threads(1)
    saved = torch.load(args.network, weights_only=False)
    net = build_q_network(tuple(saved["shape"]), 9, cnn=saved["cnn"])
    net.load_state_dict(saved["state"])
    net.eval()

    def greedy(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.from_numpy(obs)).argmax(1).numpy()

    env_cfg = dataclasses.replace(EnvConfig(scenario="straight", reward_preset=5, initial_lane="random", max_steps=300),
                                  **json.loads(args.env_kwargs))
    # The project's own greedy evaluation (what `laneshift eval` and the protocol's tests run).
    result = evaluate_policy(lambda env: GreedyPolicy(greedy), env_cfg, args.episodes, seed=200_000)
    print(json.dumps({"network": args.network, "episodes": args.episodes, "survival": result["survival_rate"],
                      "achievement": result["achievement_rate"], "initial_lane": env_cfg.initial_lane}))


if __name__ == "__main__":
    main()
