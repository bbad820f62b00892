"""Scenario ``allroads``: the four lane-change roads in one env, one road per episode, so that one
network learns to drive all four (``laneshift/AllRoadsLaneChange-v0``).

Which road: ``reset(seed=s)`` drives ``ALLROADS[s % 4]`` (straight, merge, curve, roundabout) and
resets that road's own env with the same seed ``s``, so episode seed ``s`` is the same road and the
same episode in every evaluation, and the very episode ``s`` of the single-road scenario (same
kwargs). ``reset()`` without a seed draws the road and the road env's seed from this env's
generator (seeded by the last seeded reset: a worker's episodes are reproducible). ``road="merge"``
(``env.road``) pins every episode to one road; ``reset(options={"road": ...})`` pins one episode.

What tells the network the road: the vector observation is the road env's own (82 floats by
default; the same layout on all four roads, checked when the env is built) followed by a one-hot of
the road, 4 floats in the order of ``ALLROADS``. Vector observations only: a grayscale frame has no
place for the one-hot, so ``observation="grayscale"`` is refused.

Every other kwarg goes to all four road envs (``max_steps`` defaults to 300 on every road, the test
episodes' length); ``info["road"]`` names the episode's road. Attributes this env does not have
(``ego``, ``layout``, ``target_lane``, ``lane_neighbours``, ``policy_frequency`` ...) are read from
the current road's env, ``road_env``, so that drivers reading the simulator state drive it too.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from laneshift.envspec import ALLROADS

from .lane_change import (CurveLaneChangeEnv, LaneChangeEnv, MergeLaneChangeEnv, RoundaboutLaneChangeEnv,
                          StraightLaneChangeEnv)
from .policy_vehicles import NpcPolicy
from .observations import OBS_LIMIT

ROAD_ENVS: dict[str, type[LaneChangeEnv]] = {
    "straight": StraightLaneChangeEnv, "merge": MergeLaneChangeEnv, "curve": CurveLaneChangeEnv,
    "roundabout": RoundaboutLaneChangeEnv}
assert tuple(ROAD_ENVS) == ALLROADS


def road_of_seed(seed: int) -> str:
    """The road an episode reset with ``seed`` drives (unless a road is pinned)."""
    return ALLROADS[int(seed) % len(ALLROADS)]


def _check_road(road: Any, where: str) -> str | None:
    if road is None or road == "":
        return None
    if road not in ALLROADS:
        raise ValueError(f"{where} must be one of {', '.join(ALLROADS)} (or empty: each episode draws one), "
                         f"got {road!r}")
    return str(road)


def _with_road(fn: NpcPolicy, onehot: np.ndarray) -> Callable[[np.ndarray], Any]:
    """``fn`` for a road env's policy vehicles: their observations get the road's one-hot too."""
    return lambda batch: fn(np.concatenate([batch, np.broadcast_to(onehot, (len(batch), onehot.size))], axis=1))


class AllRoadsLaneChangeEnv(gym.Env):
    """The four lane-change roads, one per episode, with the road's one-hot in the observation."""

    metadata = LaneChangeEnv.metadata
    DEFAULT_MAX_STEPS = 300

    def __init__(self, road: str | None = None, observation: str = "vector", max_steps: int | None = None,
                 render_mode: str | None = None, **kwargs: Any) -> None:
        super().__init__()
        if observation != "vector":
            raise ValueError(f"observation: allroads takes 'vector' only (the road's one-hot is appended to it; "
                             f"a grayscale frame has no place for it), got {observation!r}")
        self.road_option = _check_road(road, "road")
        self.max_steps = self.DEFAULT_MAX_STEPS if max_steps is None else max_steps
        self.road_envs: dict[str, LaneChangeEnv] = {
            name: cls(observation="vector", max_steps=self.max_steps, render_mode=render_mode, **kwargs)
            for name, cls in ROAD_ENVS.items()}
        first = self.road_envs[ALLROADS[0]]
        for name, env in self.road_envs.items():  # one network reads them all: same layout, same actions
            if env.observation_space != first.observation_space or env.action_space != first.action_space:
                raise ValueError(f"allroads: the {name} road's spaces ({env.observation_space}, {env.action_space}) "
                                 f"differ from the {ALLROADS[0]} road's ({first.observation_space}, "
                                 f"{first.action_space}); one network cannot read both")
        self.road_features = len(ALLROADS)
        self._onehots = {name: np.eye(len(ALLROADS), dtype=np.float32)[i] for i, name in enumerate(ALLROADS)}
        size = first.observation_space.shape[0] + self.road_features
        self.observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, shape=(size,), dtype=np.float32)
        self.action_space = first.action_space
        self.render_mode = render_mode
        self.road = self.road_option or ALLROADS[0]
        self.road_env: LaneChangeEnv = self.road_envs[self.road]

    def __getattr__(self, name: str) -> Any:
        # Only names this env lacks get here: the current road's env answers for its state.
        if name.startswith("_") or name in ("road_env", "road_envs"):
            raise AttributeError(name)
        return getattr(self.road_env, name)

    def set_npc_policy(self, fn: NpcPolicy | None) -> None:
        """As :meth:`LaneChangeEnv.set_npc_policy`, on every road; ``fn`` gets this env's observations
        (the road's one-hot appended)."""
        if fn is not None and not callable(fn):
            raise ValueError(f"fn must be callable or None, got {fn!r}")
        for name, env in self.road_envs.items():
            env.set_npc_policy(None if fn is None else _with_road(fn, self._onehots[name]))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        options = dict(options or {})
        road = _check_road(options.pop("road", None), "options['road']") or self.road_option
        if seed is not None:
            inner_seed = int(seed)
            road = road or road_of_seed(inner_seed)
        else:  # both draws always, so that pinning a road leaves the seeds of the episodes as they were
            drawn = ALLROADS[int(self.np_random.integers(len(ALLROADS)))]
            inner_seed = int(self.np_random.integers(2**31 - 1))
            road = road or drawn
        self.road, self.road_env = road, self.road_envs[road]
        obs, info = self.road_env.reset(seed=inner_seed, options=options)
        return self._observe(obs), self._info(info)

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.road_env.step(action)
        return self._observe(obs), reward, terminated, truncated, self._info(info)

    def render(self) -> np.ndarray | None:
        return self.road_env.render()

    def close(self) -> None:
        for env in self.road_envs.values():
            env.close()

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        return np.concatenate([obs, self._onehots[self.road]])

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        info["road"] = self.road
        return info
