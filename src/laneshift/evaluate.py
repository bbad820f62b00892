"""Greedy evaluation of a checkpoint: survival and achievement rates (paper, Table 2).

Survival: the episode ends without a collision or leaving the road. Achievement: the agent is
in the target lane at the last step (so a crash is never an achievement). Rates come with 95 %
Wilson score intervals.

    >>> r = evaluate_checkpoint("runs/x/checkpoints/final.safetensors", EnvConfig(), episodes=20)  # doctest: +SKIP
    >>> r["survival_rate"], r["survival_ci95"]  # doctest: +SKIP
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from .config import EnvConfig
from .envspec import make_env


def wilson_ci95(successes: int, n: int) -> tuple[float, float]:
    if n == 0:
        return (0.0, 1.0)
    z = 1.959963984540054
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def evaluate_policy(policy: Callable[[np.ndarray], int], env_cfg: EnvConfig, episodes: int, seed: int = 0) -> dict:
    env = make_env(env_cfg)
    returns, lengths, survived, achieved = [], [], 0, 0
    try:
        for ep in range(episodes):
            obs, info = env.reset(seed=seed + ep)
            total, steps, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, info = env.step(int(policy(obs)))
                total += float(reward)
                steps += 1
                done = terminated or truncated
            crashed = bool(info.get("crashed", terminated))  # LKA: terminated = left the lane
            survived += not crashed
            achieved += (not crashed) and bool(info.get("on_target_lane", False))
            returns.append(total)
            lengths.append(steps)
    finally:
        env.close()
    result = {"episodes": episodes, "return_mean": float(np.mean(returns)), "return_std": float(np.std(returns)),
              "length_mean": float(np.mean(lengths)), "survival_rate": survived / episodes,
              "survival_ci95": wilson_ci95(survived, episodes)}
    if not env_cfg.is_lka:
        result.update(achievement_rate=achieved / episodes, achievement_ci95=wilson_ci95(achieved, episodes))
    return result


def load_greedy_policy(checkpoint: str | Path) -> Callable[[np.ndarray], int]:
    from laneshift.actors.policy import QPolicy
    from laneshift.learner.weights import load_checkpoint, load_into

    tensors, meta = load_checkpoint(checkpoint)
    try:
        obs_shape = tuple(int(x) for x in meta["obs_shape"].split(","))
        hidden = tuple(int(x) for x in meta["hidden"].split(",") if x)
        n_actions = int(meta["n_actions"])
    except (KeyError, ValueError):
        raise ValueError(f"checkpoint {checkpoint}: missing laneshift metadata (obs_shape, hidden, n_actions)") from None
    policy = QPolicy(obs_shape, n_actions, hidden)
    load_into(policy.net, tensors)
    return lambda obs: int(policy.greedy(np.asarray(obs)[None])[0])


def evaluate_checkpoint(checkpoint: str | Path, env_cfg: EnvConfig, episodes: int, seed: int = 0) -> dict:
    return evaluate_policy(load_greedy_policy(checkpoint), env_cfg, episodes, seed)


def format_result(r: dict) -> str:
    text = (f"{r['episodes']} episodes: return {r['return_mean']:.2f} +- {r['return_std']:.2f}, "
            f"length {r['length_mean']:.1f}, survival {r['survival_rate']:.0%}")
    if "achievement_rate" in r:
        text += f", achievement {r['achievement_rate']:.0%}"
    return text
