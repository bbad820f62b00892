"""The canonical sha256 of a demo shard's transition arrays (scheme ``laneshift-demo-v1``).

sha256 over ``b"laneshift-demo-v1\\n"`` followed, for each array in :data:`ARRAY_ORDER`
(observations, actions, rewards, next_observations, terminations, truncations, episode_ids,
with the dtypes of :class:`laneshift.demos.shard.DemoShard`), by the header line
``f"{name}:{dtype.str}:{shape joined by ','}\\n"`` and the array's bytes in C order,
little-endian. The hash covers the transitions, not the file encoding: full and frame-stack
encodings of the same data hash alike, and anyone holding the arrays can recompute it.

Example::

    >>> import numpy as np
    >>> z = np.zeros(1, np.float32)
    >>> len(transition_sha256(z[:, None], np.zeros(1, np.int64), z, z[:, None],
    ...     np.zeros(1, bool), np.zeros(1, bool), np.zeros(1, np.int32)))
    64

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

SHA256_SCHEME = "laneshift-demo-v1"
ARRAY_ORDER = (
    "observations",
    "actions",
    "rewards",
    "next_observations",
    "terminations",
    "truncations",
    "episode_ids",
)


def _little_endian(dtype: np.dtype) -> np.dtype:
    return dtype.newbyteorder("<") if dtype.byteorder == ">" else dtype


def _hash_array(digest: Any, name: str, dtype: np.dtype, shape: tuple[int, ...],
                chunks: Iterable[np.ndarray]) -> None:
    """Hash one logical array given as consecutive chunks along its first axis.

    Hashing chunk by chunk gives the same digest as hashing their concatenation, so shards are
    hashed episode by episode without building the flat arrays first.
    """
    dtype = _little_endian(np.dtype(dtype))
    digest.update(f"{name}:{dtype.str}:{','.join(str(n) for n in shape)}\n".encode())
    for chunk in chunks:
        chunk = np.ascontiguousarray(np.asarray(chunk).astype(dtype, copy=False))
        digest.update(chunk.reshape(-1).view(np.uint8))


def transition_sha256(
    observations: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray,
    next_observations: np.ndarray,
    terminations: np.ndarray,
    truncations: np.ndarray,
    episode_ids: np.ndarray,
) -> str:
    """The canonical sha256 of a shard's flat transition arrays (see the module docstring)."""
    digest = hashlib.sha256(SHA256_SCHEME.encode() + b"\n")
    arrays = (observations, actions, rewards, next_observations, terminations, truncations,
              episode_ids)
    for name, array in zip(ARRAY_ORDER, arrays):
        array = np.asarray(array)
        _hash_array(digest, name, array.dtype, array.shape, [array])
    return digest.hexdigest()


def arrays_sha256(arrays: Mapping[str, np.ndarray]) -> str:
    """:func:`transition_sha256` of a mapping holding the arrays named in :data:`ARRAY_ORDER`."""
    return transition_sha256(*(arrays[name] for name in ARRAY_ORDER))


def episodes_sha256(
    observations: Sequence[np.ndarray],
    actions: Sequence[np.ndarray],
    rewards: Sequence[np.ndarray],
    terminations: Sequence[np.ndarray],
    truncations: Sequence[np.ndarray],
    obs_dtype: Any,
) -> str:
    """The same digest as :func:`transition_sha256`, from per-episode sequences.

    ``observations[e]`` is episode e's ``[T+1, ...]`` observation sequence, the other arguments
    its ``[T]`` arrays; episode ids are 0..E-1 in order. Nothing of the flat size is allocated.
    """
    lengths = [len(a) for a in actions]
    total = int(sum(lengths))
    obs_shape = tuple(observations[0].shape[1:]) if observations else ()
    digest = hashlib.sha256(SHA256_SCHEME.encode() + b"\n")
    columns = {
        "observations": (obs_dtype, (total, *obs_shape), (o[:-1] for o in observations)),
        "actions": (np.int64, (total,), actions),
        "rewards": (np.float32, (total,), rewards),
        "next_observations": (obs_dtype, (total, *obs_shape), (o[1:] for o in observations)),
        "terminations": (np.bool_, (total,), terminations),
        "truncations": (np.bool_, (total,), truncations),
        "episode_ids": (np.int32, (total,),
                        (np.full(n, e, np.int32) for e, n in enumerate(lengths))),
    }
    for name in ARRAY_ORDER:
        dtype, shape, chunks = columns[name]
        _hash_array(digest, name, np.dtype(dtype), shape, chunks)
    return digest.hexdigest()
