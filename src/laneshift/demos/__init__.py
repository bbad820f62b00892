"""Human / scripted demonstrations ("prior knowledge") for laneshift's replay buffer.

A demo shard is a Minari dataset (hdf5 backend, its own dataset id) in a directory of its own;
see ``docs/demos.md``. The shard format (``shard``, ``checksum``, ``framestack``, ``outcomes``,
``envsupport``) is part of the contract every process shares; the rest (``writer``,
``generate``, ``record``, ``humanlike``, ``cli``) are tools. Demonstrators: a person at the keyboard (``record``), the scripted
expert and a human-like stand-in for a person (``generate``, ``policy="human-like"``).

Example::

    >>> from laneshift.demos import generate_shard, load_shard
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

# The writers are imported on first use (PEP 562): a process that only reads shards (the replay
# server, through ``laneshift.demos.shard``) never imports the env-running generator.
_LAZY = {"write_shard": ".writer", "generate_shard": ".generate"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

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
