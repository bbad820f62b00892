"""What a run's environment looks like on the wire, derived from the env itself.

    >>> from laneshift.config import EnvConfig
    >>> spec = env_spec(EnvConfig(scenario="lka"))  # doctest: +SKIP
    >>> spec.schema.n_actions  # doctest: +SKIP
    31
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from .config import EnvConfig
from .wire import TransitionSchema


@dataclass(frozen=True)
class EnvSpec:
    env_id: str
    schema: TransitionSchema
    env_kwargs: tuple[tuple[str, object], ...]


def make_env(cfg: EnvConfig, **extra) -> gym.Env:
    from laneshift.actors.envs import make_env as _make  # imports highway-env: keep it lazy

    return _make(cfg.scenario, **{**cfg.env_kwargs(), **extra})


@functools.lru_cache(maxsize=16)
def env_spec(cfg: EnvConfig) -> EnvSpec:
    """Build the env once and read its spaces (cached per config)."""
    env = make_env(cfg)
    try:
        obs_space, act_space = env.observation_space, env.action_space
        if not isinstance(act_space, gym.spaces.Discrete):
            raise ValueError(f"env.scenario {cfg.scenario}: DQN needs a Discrete action space, got {act_space}")
        schema = TransitionSchema(obs_shape=tuple(obs_space.shape), obs_dtype=np.dtype(obs_space.dtype).str,
                                  n_actions=int(act_space.n))
        return EnvSpec(env.spec.id if env.spec else cfg.scenario, schema, tuple(sorted(cfg.env_kwargs().items())))
    finally:
        env.close()
