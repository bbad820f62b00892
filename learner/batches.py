"""The learner's side of a sample request: how long to wait after a refusal, and a sampled
batch cut into the batches of its updates.

A replay server answers a ``SampleRequest`` with a ``SampledBatch``, a refusal (a ``WireError``:
not ready, rate limited, with ``retry_after_ms`` when it knows how long) or nothing (no answer in
time). Every sampler of the learner (the async mode's prefetch thread, pre-training, the sync
rounds) waits a refusal out by ``retry_delay``, so the back-off is written here alone.

Room: learner (component). May import: numpy, the contract (``laneshift.wire``); never another
component.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from laneshift import wire

#: A replay client's ``sample``: a batch, a refusal, or None (no answer).
Sample = Callable[[wire.SampleRequest], "wire.SampledBatch | wire.WireError | None"]

#: The wait when the replay server did not answer at all.
NO_ANSWER_WAIT_S = 0.1

#: The largest sample reply the learner asks for. glibc hands a freed block out again only up to its
#: 32 MB mmap ceiling; a larger reply buffer (the replay server's, and the learner's copy) is mapped
#: and page-faulted anew for every reply. Over zenoh on a 2-core machine, 41 MB pixel replies (4
#: batches of 128 rows) cost 30.7 ms per 128 rows against 19.2 ms for 20 MB replies
#: (docs/results/pixels-gpu/sample_cost.py).
MAX_REPLY_BYTES = 30 * 2**20


def batches_per_request(batch_size: int, prefetch: int, obs_shape: tuple[int, ...], obs_dtype: str) -> int:
    """``learner.prefetch`` batches per sample request, fewer where their reply would pass
    ``MAX_REPLY_BYTES`` (a row carries two observations); at least one.

    >>> batches_per_request(128, 4, (4, 100, 100), "|u1"), batches_per_request(256, 4, (82,), "<f4")
    (3, 4)
    """
    row_bytes = 2 * math.prod(obs_shape) * np.dtype(obs_dtype).itemsize
    return max(1, min(prefetch, MAX_REPLY_BYTES // max(1, batch_size * row_bytes)))


def retry_delay(refusal: wire.WireError | None) -> float:
    """Seconds to wait before asking again: as long as the replay server asked
    (``retry_after_ms``), ``NO_ANSWER_WAIT_S`` if it did not answer; at least 1 ms.

    >>> err = wire.WireError("rate_limited", "filling"); err.retry_after_ms = 250
    >>> retry_delay(err), retry_delay(None), retry_delay(wire.WireError("not_ready", "x"))
    (0.25, 0.1, 0.001)
    """
    delay = getattr(refusal, "retry_after_ms", 0) / 1000 if refusal is not None else NO_ANSWER_WAIT_S
    return max(delay, 0.001)


def sample_or_wait(sample: Sample, req: wire.SampleRequest, wait: Callable[[float], Any]) -> wire.SampledBatch | None:
    """One request: the batch, or None after waiting the refusal out with ``wait(seconds)`` (a
    ``threading.Event.wait``, so a stop ends the wait at once)."""
    result = sample(req)
    if isinstance(result, wire.SampledBatch):
        return result
    wait(retry_delay(result))
    return None


#: The per-row fields of a sampled batch that DoubleDQN.update reads.
UPDATE_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "steps", "weight", "is_demo")


def split_updates(batch: wire.SampledBatch) -> list[dict[str, np.ndarray]]:
    """The batch's ``num_batches`` update batches: row slices (views, no copies) of each field
    (no ``next_obs`` where the batch has none: a SampleRequest with next_obs=False)."""
    fields = {k: getattr(batch, k) for k in UPDATE_FIELDS if getattr(batch, k) is not None}
    rows, rest = divmod(len(batch.action), batch.num_batches)
    if rest:
        raise ValueError(f"{len(batch.action)} rows do not split into {batch.num_batches} batches")
    return [{k: v[i * rows:(i + 1) * rows] for k, v in fields.items()} for i in range(batch.num_batches)]
