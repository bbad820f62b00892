"""Human / scripted demonstrations ("prior knowledge") for laneshift's replay buffer.

A demo shard is a Minari dataset (hdf5 backend, its own dataset id) in a directory of its own;
see ``docs/demos.md``. Demonstrators: a person at the keyboard (``record``), the scripted
expert and a human-like stand-in for a person (``generate``, ``policy="human-like"``).

Example::

    >>> from laneshift.demos import generate_shard, load_shard
    >>> path = generate_shard("runs/demos/straight", env_id_or_scenario="straight",
    ...     env_kwargs={"observation": "vector"}, episodes=5, seed=0)   # doctest: +SKIP
    >>> shard = load_shard(path, n_actions=9)                           # doctest: +SKIP
"""

from .shard import (
    DATASET_ID,
    LEGACY_DATASET_ID,
    DemoShard,
    ShardError,
    load_shard,
    load_shards,
    shard_dataset_id,
)
from .writer import write_shard
from .generate import generate_shard

__all__ = [
    "DATASET_ID",
    "LEGACY_DATASET_ID",
    "DemoShard",
    "ShardError",
    "generate_shard",
    "load_shard",
    "load_shards",
    "shard_dataset_id",
    "write_shard",
]
