"""laneshift environments: the paper's four lane-change scenarios, all four in one (``allroads``) and
the MATLAB LKA plant.

Importing this package registers the gymnasium ids below, so that
``gym.make("laneshift.actors.envs:laneshift/StraightLaneChange-v0")`` (or, once
``laneshift.actors`` imports this package, ``"laneshift.actors:laneshift/..."``) works in a fresh
process such as a Ray worker.  Registration is lazy: the env modules are imported by ``gym.make``.

``make(cfg)`` builds a run's env from its ``EnvConfig``; ``spec_of(cfg)`` reads the env's
observation and action spaces into the contract's ``EnvSpec``, for whoever launches the processes
that never build a simulator themselves (the replay server, the learner).

Room: actors (the env-running component). May import: the contract (``laneshift.config``,
``laneshift.envspec``, ``laneshift.wire``), gymnasium, highway-env, numpy.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

if TYPE_CHECKING:
    from laneshift.config import EnvConfig
    from laneshift.envspec import EnvSpec

from .deferred_imports import defer_unused_imports, load_deferred

# Before highway-env is imported (by the env modules gym.make loads): pandas and pyplot, which it
# imports and laneshift's envs never use, stay unloaded until touched (deferred_imports.py).
defer_unused_imports()

from .actions import META_ACTIONS, PAPER_ACTIONS, paper_action_index  # noqa: E402
from .rewards import REWARD_PRESETS, RewardPreset, compute_reward  # noqa: E402

from laneshift.envspec import SCENARIOS  # noqa: E402 - scenario name -> gymnasium id (the contract's)

_ENTRY_POINTS: dict[str, str] = {
    "laneshift/StraightLaneChange-v0": "laneshift.actors.envs.lane_change:StraightLaneChangeEnv",
    "laneshift/MergeLaneChange-v0": "laneshift.actors.envs.lane_change:MergeLaneChangeEnv",
    "laneshift/CurveLaneChange-v0": "laneshift.actors.envs.lane_change:CurveLaneChangeEnv",
    "laneshift/RoundaboutLaneChange-v0": "laneshift.actors.envs.lane_change:RoundaboutLaneChangeEnv",
    "laneshift/AllRoadsLaneChange-v0": "laneshift.actors.envs.allroads:AllRoadsLaneChangeEnv",
    "laneshift/LaneKeepingAssist-v0": "laneshift.actors.envs.lka:LaneKeepingAssistEnv",
}


def _register() -> None:
    # No max_episode_steps: the envs truncate themselves at `max_steps`, so gym.make adds no
    # TimeLimit wrapper whose limit could disagree with the env's own.
    for env_id, entry_point in _ENTRY_POINTS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point)


_register()


def make_env(scenario_or_id: str, **kwargs: Any) -> gym.Env:
    """Create an env from a scenario name ("straight", "merge", "curve", "roundabout", "allroads", "lka") or
    a gymnasium id; keyword arguments go to the env constructor."""
    env_id = SCENARIOS.get(scenario_or_id, scenario_or_id)
    if env_id not in _ENTRY_POINTS and env_id not in gym.registry:
        raise ValueError(
            f"scenario_or_id: unknown {scenario_or_id!r}; expected one of {sorted(SCENARIOS)} "
            "or a registered gymnasium id"
        )
    if env_id not in _ENTRY_POINTS:  # a stock env may use pandas (its Kinematics observation)
        load_deferred()
    return gym.make(env_id, **kwargs)


def make(cfg: EnvConfig, **extra: Any) -> gym.Env:
    """The run's env, as configured (``extra``: e.g. ``render_mode``)."""
    return make_env(cfg.scenario, **{**cfg.env_kwargs(), **extra})


@functools.lru_cache(maxsize=16)
def spec_of(cfg: EnvConfig) -> EnvSpec:
    """Build the env once and read its spaces (cached per config): what the launcher computes
    once and hands to the components (highway-env's import and one env: ~2.4 s, ~60 MB)."""
    from laneshift.envspec import EnvSpec
    from laneshift.wire import TransitionSchema

    env = make(cfg)
    try:
        obs_space, act_space = env.observation_space, env.action_space
        if not isinstance(act_space, gym.spaces.Discrete):
            raise ValueError(f"env.scenario {cfg.scenario}: DQN needs a Discrete action space, got {act_space}")
        schema = TransitionSchema(obs_shape=tuple(obs_space.shape), obs_dtype=np.dtype(obs_space.dtype).str,
                                  n_actions=int(act_space.n))
        return EnvSpec(env.spec.id if env.spec else cfg.scenario, schema, tuple(sorted(cfg.env_kwargs().items())))
    finally:
        env.close()


__all__ = [
    "META_ACTIONS",
    "PAPER_ACTIONS",
    "REWARD_PRESETS",
    "SCENARIOS",
    "RewardPreset",
    "compute_reward",
    "make",
    "make_env",
    "paper_action_index",
    "spec_of",
]
