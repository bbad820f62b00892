"""Load demo shards (Minari datasets) into the replay server's fixed demo table.

Shards are validated against the run's env (id, observation shape and dtype, action count)
and their sha256 is checked; a mismatch refuses the start with a message naming it. With
``n_step > 1`` the shard's transitions become n-step items within each recorded episode
(laneshift.nstep), the same items the actors send.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import numpy as np

from laneshift.config import EnvConfig
from laneshift.envspec import EnvSpec
from laneshift.nstep import nstep_arrays

from .frames import fixed_stack_views
from .storage import DemoTable


def load_demo_table(paths: tuple[str, ...] | list[str], spec: EnvSpec, n_step: int = 1,
                    gamma: float = 0.99) -> DemoTable:
    from laneshift.demos.shard import ShardError, load_shards

    try:
        shard = load_shards(list(paths), env_id=spec.env_id, obs_shape=spec.schema.obs_shape,
                            obs_dtype=np.dtype(spec.schema.obs_dtype), n_actions=spec.schema.n_actions)
    except ShardError as exc:
        raise ValueError(f"replay.demo_paths: {exc}") from None
    # Rewards and action meanings depend on these: a shard made under others would teach wrong values.
    # A kwarg not given when recording means the env's default, which EnvConfig's defaults mirror.
    defaults = {"reward_preset": EnvConfig.reward_preset, "action_set": EnvConfig.action_set}
    recorded = {**defaults, **(shard.metadata.get("env_kwargs") or {})}
    run_kwargs = {**defaults, **dict(spec.env_kwargs)}
    for key in defaults if "reward_preset" in dict(spec.env_kwargs) else ():  # lane-change envs only
        if recorded[key] != run_kwargs[key]:
            raise ValueError(f"replay.demo_paths: the demo shard was recorded with {key}={recorded[key]!r}, "
                             f"the run uses {key}={run_kwargs[key]!r}")
    reward = np.asarray(shard.rewards, np.float32)
    next_obs = shard.next_observations
    terminated = np.asarray(shard.terminations, np.uint8)
    steps = np.ones(reward.shape[0], np.uint8)
    if n_step > 1:
        reward, next_obs, terminated, steps = nstep_arrays(reward, next_obs, terminated, shard.episode_ids,
                                                           n_step, gamma)
    obs, next_obs = np.ascontiguousarray(shard.observations), np.ascontiguousarray(next_obs)
    if obs.ndim == 4:  # stacked frames: each distinct frame held once (80 KB -> ~10 KB an item, frames.py)
        obs, next_obs = fixed_stack_views(obs, next_obs)
    return DemoTable(obs=obs, action=np.asarray(shard.actions, np.int64),
                     reward=reward, next_obs=next_obs, terminated=terminated,
                     sha256=shard.sha256, metadata=dict(shard.metadata), steps=steps)
