"""The learner's side of the replay: SAMPLE_REQUEST (learner -> replay server), BATCH (its reply,
with the canonical-form fast paths of ``.fastpath``) and PRIORITIES (new priorities of sampled
items, prioritized sampling).

Room: the contract (shared by every process). May import: numpy, the standard library,
``laneshift.config`` (the name rule), ``.errors``, ``.envelope``, ``.batches`` and ``.fastpath``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import NAME
from .batches import BATCH_FIELDS, SampledBatch, TransitionSchema
from .envelope import MAX_BATCH_ROWS, Kind, decode, encode, require_field
from .errors import WireError
from .fastpath import fast_batch, fast_encode_batch


@dataclass(frozen=True)
class SampleRequest:
    batch_size: int
    num_batches: int = 1
    # Sync parallel mode: serve only once every listed actor delivered a batch made with
    # weights version >= min_version (the MATLAB "host waits for every worker").
    min_version: int = -1
    actors: tuple[str, ...] = ()
    # False: the reply leaves the next observations out (``SampledBatch.next_obs`` None), for an
    # update that reads none (phase 1 of the imitation losses alone, learner.phase1_td=false): half
    # the bytes of a frame batch to gather, encode, route and decode.
    next_obs: bool = True

    def __post_init__(self) -> None:
        if not 1 <= self.batch_size <= MAX_BATCH_ROWS or not 1 <= self.num_batches <= 64:
            raise WireError("bad_request", f"batch_size {self.batch_size} / num_batches {self.num_batches} out of range")
        if self.batch_size * self.num_batches > MAX_BATCH_ROWS:
            raise WireError("bad_request", "batch_size * num_batches too large")
        if not isinstance(self.next_obs, bool):
            raise WireError("bad_request", f"next_obs must be true or false, got {self.next_obs!r}")


def encode_sample_request(req: SampleRequest) -> bytes:
    return encode(Kind.SAMPLE_REQUEST, {"batch_size": req.batch_size, "num_batches": req.num_batches,
                                        "min_version": req.min_version, "actors": list(req.actors),
                                        "next_obs": req.next_obs})


def decode_sample_request(data: bytes | bytearray | memoryview) -> SampleRequest:
    msg = decode(data, expect=Kind.SAMPLE_REQUEST)
    h = msg.header
    actors = h.get("actors", [])
    if not isinstance(actors, list) or not all(isinstance(x, str) and NAME.fullmatch(x) for x in actors):
        raise WireError("bad_request", f"bad actors list {actors!r}")
    next_obs = h.get("next_obs", True)  # optional, like actors: absent means the whole rows
    return SampleRequest(batch_size=require_field(h, "batch_size", int, "bad_request"),
                         num_batches=require_field(h, "num_batches", int, "bad_request"),
                         min_version=require_field(h, "min_version", int, "bad_request"), actors=tuple(actors),
                         next_obs=next_obs)


def encode_batch(batch: SampledBatch) -> bytes | bytearray:
    fast = fast_encode_batch(batch)  # the same bytes, fewer copies
    if fast is not None:
        return fast
    return encode(Kind.BATCH, {"num_batches": batch.num_batches, "info": batch.info},
                  {k: getattr(batch, k) for k in BATCH_FIELDS if getattr(batch, k) is not None})


def decode_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch:
    """Decode and validate a BATCH reply (arrays: one private copy); raises WireError. The form
    ``encode_batch`` writes takes a fast path (see ``fast_transitions``), the rest the generic one."""
    batch = fast_batch(data, schema)
    return batch if batch is not None else _checked_batch(data, schema)


def _checked_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch:
    msg = decode(data, expect=Kind.BATCH)
    # Every field, or every field but next_obs (the reply to a SampleRequest with next_obs=False).
    if set(msg.arrays) not in (set(BATCH_FIELDS), set(BATCH_FIELDS) - {"next_obs"}):
        raise WireError("bad_arrays", f"batch arrays {sorted(msg.arrays)}")
    if msg.arrays["action"].ndim != 1:
        raise WireError("bad_shape", f"batch action must be 1-D, got shape {msg.arrays['action'].shape}")
    rows = msg.arrays["action"].shape[0]
    for name in [n for n in ("obs", "next_obs") if n in msg.arrays]:
        if msg.arrays[name].shape != (rows, *schema.obs_shape) or msg.arrays[name].dtype.str != schema.obs_dtype:
            raise WireError("bad_shape", f"batch {name} {msg.arrays[name].shape} does not fit the schema")
    for name in BATCH_FIELDS[1:]:
        if name not in ("next_obs",) and msg.arrays[name].shape != (rows,):
            raise WireError("bad_shape", f"batch {name} shape {msg.arrays[name].shape}")
    steps = msg.arrays["steps"]
    if steps.dtype.str != "|u1" or (rows and steps.min() < 1):
        raise WireError("bad_value", "batch steps must be uint8 >= 1")
    nb = require_field(msg.header, "num_batches", int)
    if nb < 1 or rows % nb:
        raise WireError("bad_header", f"{rows} rows do not split into {nb} batches")
    return SampledBatch(num_batches=nb, info=msg.header.get("info", {}), **msg.arrays)


# --------------------------------------------------------------------------- priorities



@dataclass(frozen=True)
class PriorityUpdate:
    index: np.ndarray  # int64 item keys as sampled (SampledBatch.index)
    is_demo: np.ndarray  # uint8, as sampled
    priority: np.ndarray  # float32 >= 0, e.g. |TD error|


def encode_priorities(update: PriorityUpdate) -> bytes:
    return encode(Kind.PRIORITIES, {}, {"index": np.asarray(update.index, np.int64),
                                        "is_demo": np.asarray(update.is_demo, np.uint8),
                                        "priority": np.asarray(update.priority, np.float32)})


def decode_priorities(data: bytes | bytearray | memoryview) -> PriorityUpdate:
    msg = decode(data, expect=Kind.PRIORITIES)
    a = msg.arrays
    if set(a) != {"index", "is_demo", "priority"}:
        raise WireError("bad_arrays", f"priorities arrays {sorted(a)}")
    rows = a["index"].shape[0] if a["index"].ndim == 1 else -1
    if not 1 <= rows <= MAX_BATCH_ROWS:
        raise WireError("bad_shape", f"index must be 1-D with 1..{MAX_BATCH_ROWS} rows")
    for name, code in (("index", "<i8"), ("is_demo", "|u1"), ("priority", "<f4")):
        if a[name].shape != (rows,) or a[name].dtype.str != code:
            raise WireError("bad_shape", f"{name} must be {code} of shape ({rows},)")
    if a["is_demo"].max() > 1 or a["index"].min() < 0:
        raise WireError("bad_value", "is_demo must be 0/1 and index >= 0")
    if not np.isfinite(a["priority"]).all() or (a["priority"] < 0).any():
        raise WireError("non_finite", "priorities must be finite and >= 0")
    return PriorityUpdate(**a)
