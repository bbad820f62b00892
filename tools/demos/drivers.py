"""Drivers and one episode of driving, shared by the demo generator (``generate``) and the
human-like stand-in (``humanlike``), which both import this module and not each other's.

A driver is ``driver(obs) -> action index``; a policy factory ``policy(env) -> driver`` (one
fresh driver per episode). ``scripted_driver(env)`` is laneshift's scripted expert for ``env``;
``run_episode`` drives one episode and returns it in ``writer.write_shard``'s episode format.

Imports: numpy, gymnasium; laneshift's demonstrators lazily (they live with the envs).

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

Driver = Callable[[Any], Any]  # observation -> action index
PolicyFactory = Callable[[gym.Env], Driver]  # env -> driver, like ScriptedDriver(env)


def scripted_driver(env: gym.Env) -> Driver:
    """laneshift's scripted expert for ``env``: ScriptedDriver for the lane-change scenarios,
    LKAExpert for lane keeping (imported lazily: they live with the envs)."""
    try:
        from laneshift.actors.envs.demonstrator import LKAExpert, ScriptedDriver
        from laneshift.actors.envs.lka import LaneKeepingAssistEnv
    except ImportError as exc:
        raise ValueError(f"policy 'scripted' needs laneshift.actors.envs.demonstrator: {exc}") from exc
    if isinstance(env.unwrapped, LaneKeepingAssistEnv):
        return LKAExpert(env)
    return ScriptedDriver(env)  # refuses, with a clear message, envs it cannot drive


def run_episode(env: gym.Env, driver: Driver, seed: int | None) -> dict[str, Any]:
    """Drive one episode to its end and return it in ``write_shard``'s episode format."""
    obs, info = env.reset(seed=seed)
    return drive_to_end(env, driver, obs, info)


def drive_to_end(env: gym.Env, driver: Driver, obs: Any, info: dict) -> dict[str, Any]:
    """Let ``driver`` drive from ``obs`` (with its ``info``) to the episode's end; the part driven,
    in ``write_shard``'s episode format."""
    # Copies: highway-env returns the same (mutated) array object every step.
    observations = [np.array(obs, copy=True)]
    actions, rewards, terminations, truncations, infos = [], [], [], [], [info]
    while True:
        action = int(driver(obs))
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(np.array(obs, copy=True))
        actions.append(action)
        rewards.append(float(reward))
        terminations.append(bool(terminated))
        truncations.append(bool(truncated))
        infos.append(info)
        if terminated or truncated:
            break
    return {
        "observations": np.stack(observations),
        "actions": np.asarray(actions, np.int64),
        "rewards": np.asarray(rewards, np.float64),
        "terminations": np.asarray(terminations, bool),
        "truncations": np.asarray(truncations, bool),
        "infos": infos,
    }
