"""laneshift environments: the paper's four lane-change scenarios and the MATLAB LKA plant.

Importing this package registers the gymnasium ids below, so that
``gym.make("laneshift.actors.envs:laneshift/StraightLaneChange-v0")`` (or, once
``laneshift.actors`` imports this package, ``"laneshift.actors:laneshift/..."``) works in a fresh
process such as a Ray worker.  Registration is lazy: the env modules are imported by ``gym.make``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from .actions import META_ACTIONS, PAPER_ACTIONS, paper_action_index
from .rewards import REWARD_PRESETS, RewardPreset, compute_reward

#: Scenario name -> gymnasium id.
SCENARIOS: dict[str, str] = {
    "straight": "laneshift/StraightLaneChange-v0",
    "merge": "laneshift/MergeLaneChange-v0",
    "curve": "laneshift/CurveLaneChange-v0",
    "roundabout": "laneshift/RoundaboutLaneChange-v0",
    "lka": "laneshift/LaneKeepingAssist-v0",
}

_ENTRY_POINTS: dict[str, str] = {
    "laneshift/StraightLaneChange-v0": "laneshift.actors.envs.lane_change:StraightLaneChangeEnv",
    "laneshift/MergeLaneChange-v0": "laneshift.actors.envs.lane_change:MergeLaneChangeEnv",
    "laneshift/CurveLaneChange-v0": "laneshift.actors.envs.lane_change:CurveLaneChangeEnv",
    "laneshift/RoundaboutLaneChange-v0": "laneshift.actors.envs.lane_change:RoundaboutLaneChangeEnv",
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
    """Create an env from a scenario name ("straight", "merge", "curve", "roundabout", "lka") or
    a gymnasium id; keyword arguments go to the env constructor."""
    env_id = SCENARIOS.get(scenario_or_id, scenario_or_id)
    if env_id not in _ENTRY_POINTS and env_id not in gym.registry:
        raise ValueError(
            f"scenario_or_id: unknown {scenario_or_id!r}; expected one of {sorted(SCENARIOS)} "
            "or a registered gymnasium id"
        )
    return gym.make(env_id, **kwargs)


__all__ = [
    "META_ACTIONS",
    "PAPER_ACTIONS",
    "REWARD_PRESETS",
    "SCENARIOS",
    "RewardPreset",
    "compute_reward",
    "make_env",
    "paper_action_index",
]
