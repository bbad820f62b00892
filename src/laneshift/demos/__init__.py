"""Human / scripted demonstrations ("prior knowledge") for laneshift's replay buffer.

A demo shard is a Minari dataset (hdf5 backend, its own dataset id) in a directory of its own;
see ``docs/demos.md``. This package is the shard format (``shard``, ``checksum``, ``framestack``,
``outcomes``, ``envsupport``), part of the contract every process shares. What makes and reads
shards for a person (the writer, the scripted and human-like generators, the keyboard recorder,
``laneshift demos``) are tools, in ``laneshift.tools.demos``.

Example::

    >>> from laneshift.tools.demos.generate import generate_shard
    >>> from laneshift.demos import load_shard
    >>> path = generate_shard("runs/demos/straight", env_id_or_scenario="straight",
    ...     env_kwargs={"observation": "vector"}, episodes=5, seed=0)   # doctest: +SKIP
    >>> shard = load_shard(path, n_actions=9)                           # doctest: +SKIP

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
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

__all__ = [
    "DATASET_ID",
    "LEGACY_DATASET_ID",
    "DemoShard",
    "ShardError",
    "load_shard",
    "load_shards",
    "shard_dataset_id",
]
