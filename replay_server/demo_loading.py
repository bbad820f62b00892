"""Load demo shards (Minari datasets) into the replay server's fixed demo table.

Shards are validated against the run's env (id, observation shape and dtype, action count)
and their sha256 is checked; a mismatch refuses the start with a message naming it.
"""

from __future__ import annotations

import numpy as np

from laneshift.envspec import EnvSpec

from .storage import DemoTable


def load_demo_table(paths: tuple[str, ...] | list[str], spec: EnvSpec) -> DemoTable:
    from laneshift.demos.shard import ShardError, load_shards

    try:
        shard = load_shards(list(paths), env_id=spec.env_id, obs_shape=spec.schema.obs_shape,
                            obs_dtype=np.dtype(spec.schema.obs_dtype), n_actions=spec.schema.n_actions)
    except ShardError as exc:
        raise ValueError(f"replay.demo_paths: {exc}") from None
    return DemoTable(obs=np.ascontiguousarray(shard.observations),
                     action=np.asarray(shard.actions, np.int64),
                     reward=np.asarray(shard.rewards, np.float32),
                     next_obs=np.ascontiguousarray(shard.next_observations),
                     terminated=np.asarray(shard.terminations, np.uint8),
                     sha256=shard.sha256, metadata=dict(shard.metadata))
