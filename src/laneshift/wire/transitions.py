"""TRANSITIONS messages (actor -> replay server): the encoder and the validating decoder, which
takes the canonical-form fast path (``.fastpath``) where it can and the generic checks otherwise.

Room: the contract (shared by every process). May import: numpy, the standard library,
``laneshift.config`` (the name rule), ``.errors``, ``.envelope``, ``.batches`` and ``.fastpath``.
"""

from __future__ import annotations

import numpy as np

from ..config import NAME
from .batches import TransitionBatch, TransitionSchema
from .envelope import Kind, decode, encode, require_field
from .errors import WireError
from .fastpath import fast_transitions


def encode_transitions(batch: TransitionBatch) -> bytes:
    header = {"actor": batch.actor, "seq": int(batch.seq), "weights_version": int(batch.weights_version),
              "phase": int(batch.phase), "env_steps": int(batch.env_steps), "extra": batch.extra}
    return encode(Kind.TRANSITIONS, header, {
        "obs": batch.obs, "action": np.asarray(batch.action, np.int64), "reward": np.asarray(batch.reward, np.float32),
        "next_obs": batch.next_obs, "terminated": np.asarray(batch.terminated, np.uint8),
        "truncated": np.asarray(batch.truncated, np.uint8), "steps": np.asarray(batch.steps, np.uint8)})


def decode_transitions(data: bytes | bytearray | memoryview, schema: TransitionSchema, *,
                       copy: bool = True) -> TransitionBatch:
    """Decode and validate a transitions message against ``schema``; raises WireError.

    The arrays are copies (one block for all of them) unless ``copy=False``: then they are views of
    ``data`` (read-only when it is ``bytes``), for a caller that copies them away before ``data``
    changes (the replay server's ingest, which writes them into its ring at once).

    A message in the form ``encode_transitions`` writes takes a fast path (``fast_transitions``); any
    other form, and anything invalid, goes through the generic checks below, which name the reason.
    """
    batch = fast_transitions(data, schema, copy)
    return batch if batch is not None else _checked_transitions(data, schema)


def _checked_transitions(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> TransitionBatch:
    msg = decode(data, expect=Kind.TRANSITIONS)
    h = msg.header
    actor = require_field(h, "actor", str)
    if not NAME.fullmatch(actor):
        raise WireError("bad_header", f"bad actor name {actor!r}")
    ints = {k: require_field(h, k, int) for k in ("seq", "weights_version", "phase", "env_steps")}
    if any(v < 0 for v in ints.values()):
        raise WireError("bad_header", f"negative counter in {ints}")
    extra = h.get("extra", {})
    if not isinstance(extra, dict):
        raise WireError("bad_header", "'extra' must be an object")
    a = msg.arrays
    expected = {"obs", "action", "reward", "next_obs", "terminated", "truncated", "steps"}
    if set(a) != expected:
        raise WireError("bad_arrays", f"arrays {sorted(a)} != {sorted(expected)}")
    rows = a["action"].shape[0] if a["action"].ndim == 1 else -1
    if not 1 <= rows <= schema.max_rows:
        raise WireError("bad_shape", f"action must be 1-D with 1..{schema.max_rows} rows, got {a['action'].shape}")
    for name in ("obs", "next_obs"):
        if a[name].shape != (rows, *schema.obs_shape):
            raise WireError("bad_shape", f"{name} shape {a[name].shape} != {(rows, *schema.obs_shape)}")
        if a[name].dtype.str != schema.obs_dtype:
            raise WireError("bad_dtype", f"{name} dtype {a[name].dtype.str} != {schema.obs_dtype}")
    for name, code in (("action", "<i8"), ("reward", "<f4"), ("terminated", "|u1"), ("truncated", "|u1"),
                       ("steps", "|u1")):
        if a[name].shape != (rows,):
            raise WireError("bad_shape", f"{name} shape {a[name].shape} != {(rows,)}")
        if a[name].dtype.str != code:
            raise WireError("bad_dtype", f"{name} dtype {a[name].dtype.str} != {code}")
    if a["action"].min() < 0 or a["action"].max() >= schema.n_actions:
        raise WireError("bad_value", f"action outside [0, {schema.n_actions})")
    if a["terminated"].max() > 1 or a["truncated"].max() > 1:
        raise WireError("bad_value", "terminated/truncated must be 0 or 1")
    if a["steps"].min() < 1:
        raise WireError("bad_value", "steps must be >= 1")
    for name in ("reward", "obs", "next_obs"):
        if a[name].dtype.kind == "f" and not np.isfinite(a[name]).all():
            raise WireError("non_finite", f"{name} contains NaN or inf")
    return TransitionBatch(actor=actor, extra=extra, **ints, **a)
