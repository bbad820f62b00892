"""Closed-loop greedy driving of a ``bc.py`` network on the straight road: validation episodes
(seeds 200,000+, never the test seeds 100,000+), a random initial lane, 300 steps; one JSON line
with survival and achievement.

    python drive.py net.pt '{"observation": "grayscale", "frame_interval": 4}' --episodes 100

Room: a study script (docs/results). May import: anything in laneshift, torch, numpy.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from laneshift.actors.envs import make_env
from laneshift.qnet import build_q_network


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("network")
    parser.add_argument("env_kwargs", help="the env's options as JSON (the shard's view)")
    parser.add_argument("--episodes", type=int, default=50)
    args = parser.parse_args()
    torch.set_num_threads(1)
    saved = torch.load(args.network, weights_only=False)
    net = build_q_network(tuple(saved["shape"]), 9, cnn=saved["cnn"])
    net.load_state_dict(saved["state"])
    net.eval()
    env = make_env("straight", reward_preset=5, initial_lane="random", **json.loads(args.env_kwargs))
    survived = achieved = 0
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=200_000 + episode)
        for _ in range(300):
            with torch.no_grad():
                action = int(net(torch.from_numpy(np.asarray(obs))[None]).argmax())
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        crashed = bool(info.get("crashed"))
        survived += not crashed
        achieved += (not crashed) and bool(info.get("on_target_lane"))
    print(json.dumps({"network": args.network, "episodes": args.episodes, "survival": survived / args.episodes,
                      "achievement": achieved / args.episodes}))


if __name__ == "__main__":
    main()
