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


#: Specs handed to this process by whoever computed them (the launcher ships the spec to the replay
#: server and the learner): a process that does not run the simulator never builds one just to
#: learn the observation's shape (highway-env's import and one env: ~2.4 s and ~60 MB each).
_KNOWN: dict[EnvConfig, EnvSpec] = {}


def spec_to_dict(spec: EnvSpec) -> dict:
    return {"env_id": spec.env_id, "obs_shape": list(spec.schema.obs_shape), "obs_dtype": spec.schema.obs_dtype,
            "n_actions": spec.schema.n_actions, "env_kwargs": [list(kv) for kv in spec.env_kwargs]}


def remember(cfg: EnvConfig, plain: dict) -> EnvSpec:
    """Take ``plain`` (``spec_to_dict``'s output) as ``cfg``'s spec in this process; it must be
    the spec of this very config (same env kwargs), else ValueError."""
    spec = EnvSpec(str(plain["env_id"]), TransitionSchema(tuple(int(d) for d in plain["obs_shape"]),
                                                          str(plain["obs_dtype"]), int(plain["n_actions"])),
                   tuple((str(k), v) for k, v in plain["env_kwargs"]))
    if spec.env_kwargs != tuple(sorted(cfg.env_kwargs().items())):
        raise ValueError(f"env spec for {cfg.scenario}: it was computed for other env settings")
    _KNOWN[cfg] = spec
    return spec


def env_spec(cfg: EnvConfig) -> EnvSpec:
    """The env's spec: as handed to this process (``remember``), else read from a built env."""
    return _KNOWN.get(cfg) or _built_spec(cfg)


@functools.lru_cache(maxsize=16)
def _built_spec(cfg: EnvConfig) -> EnvSpec:
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
