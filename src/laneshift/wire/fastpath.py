"""The canonical-form fast paths of the two array messages: TRANSITIONS and BATCH decoded (and
BATCH encoded) through one structured dtype over the array bytes, for messages in exactly the form
``envelope.encode`` writes. ``.transitions`` and ``.sampling`` try these first and fall back to
their generic checks, which name the reason for anything refused.

Room: the contract (shared by every process). May import: numpy, the standard library,
``laneshift.config`` (the name rule), ``.envelope`` and ``.batches``; never ``.transitions`` or
``.sampling`` (they import this).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

import laneshift.wire.envelope as envelope  # MAX_MESSAGE_BYTES read at call time: one limit, the envelope's

from ..config import NAME
from .batches import BATCH_FIELDS, SampledBatch, TransitionBatch, TransitionSchema
from .envelope import (ALLOWED_DTYPES, ENVELOPE, HEADER_JSON, MAGIC, MAX_BATCH_ROWS, MAX_COUNTER, MAX_HEADER_BYTES,
                       WIRE_VERSION, Kind)

# The generic decode costs ~100 us per 32-row TRANSITIONS message (JSON of the whole header with its
# array table, then seven array specs checked and copied one by one): the replay server's ingest limit.
# Our encoder always writes the array table last and in one form, so for a given schema and row count
# the header ends with a fixed text. A message whose header ends with exactly that text is decoded here:
# only the part before it is parsed as JSON, and the arrays are fields of one structured dtype over the
# array bytes. Every check of the generic path is made (the table's by the text comparison); anything
# that fails, or any other form, returns None and the caller runs the generic path, which raises with
# the usual reason. So this path accepts a subset of what the generic one accepts, never more.
#
# Why the text comparison is enough: if a header that parses to an object ends with ``,"arrays":[...]}``
# (our table: no backslash in it), that text is its last member, not part of a string (the quote
# after the comma would close a string and leave ``arrays`` outside one: not JSON); and a header
# ``P`` + that text is a JSON object exactly when ``P + "}"`` is a non-empty JSON object.

_ARRAYS_AT = ',"arrays":['


@dataclass(frozen=True)
class _Layout:
    """A canonical message's array table: the header's closing text, and a structured dtype over
    the array bytes (one field per array, plus overlapping fields that let one reduction check
    several arrays)."""

    suffix: str  # ',"arrays":[...]}', as encode() writes it
    dtype: np.dtype  # itemsize = the array bytes
    rows: int
    aligned: bool  # every array at a multiple of its item size (from a 16-aligned start)
    finite: tuple[str, ...]  # float fields to check for NaN / inf


_LAYOUTS: dict[tuple, _Layout] = {}  # (kind, schema or obs spec, suffix) -> layout; canonical ones only
_MAX_LAYOUTS = 256
_ACTION_ROWS = re.compile(r'"name":"action","dtype":"<i8","shape":\[([0-9]{1,9})\]')


def _layout(specs: list[tuple[str, str, tuple[int, ...]]], overlays: list[tuple[str, str, int, str]],
            finite: tuple[str, ...], rows: int) -> _Layout | None:
    """``specs``: (name, dtype code, shape) in wire order; ``overlays``: (name, code, count, at field)."""
    if any(code not in ALLOWED_DTYPES or len(shape) > 8 or not all(0 <= d < 2**31 for d in shape)
           for _, code, shape in specs):
        return None  # the generic path refuses these (bad_dtype / bad_shape)
    table = [{"name": n, "dtype": c, "shape": list(sh)} for n, c, sh in specs]
    suffix = _ARRAYS_AT[:-1] + json.dumps(table, separators=(",", ":")) + "}"
    names, formats, offsets, at, offset, aligned = [], [], [], {}, 0, True
    for name, code, shape in specs:
        dt = np.dtype(code)
        names.append(name), formats.append((dt, shape)), offsets.append(offset)
        at[name] = offset
        aligned &= offset % dt.itemsize == 0
        offset += math.prod(shape) * dt.itemsize
    for name, code, count, where in overlays:
        names.append(name), formats.append((np.dtype(code), (count,))), offsets.append(at[where])
    try:
        dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": offset})
    except (ValueError, TypeError):  # e.g. a zero-sized observation: leave it to the generic path
        return None
    return _Layout(suffix, dtype, rows, aligned, finite)


def _transitions_layout(schema: TransitionSchema, rows: int) -> _Layout | None:
    obs = (rows, *schema.obs_shape)
    specs = [("obs", schema.obs_dtype, obs), ("action", "<i8", (rows,)), ("reward", "<f4", (rows,)),
             ("next_obs", schema.obs_dtype, obs), ("terminated", "|u1", (rows,)), ("truncated", "|u1", (rows,)),
             ("steps", "|u1", (rows,))]
    # action read as unsigned: a negative action is huge, so one max() checks both bounds;
    # terminated and truncated are adjacent: one max(). reward and next_obs are adjacent too:
    # with float32 observations one reduction checks both for NaN / inf.
    overlays = [("action_u", "<u8", rows, "action"), ("flags", "|u1", 2 * rows, "terminated")]
    if schema.obs_dtype == "<f4":
        overlays.append(("reward_next", "<f4", rows * (1 + math.prod(schema.obs_shape)), "reward"))
        finite: tuple[str, ...] = ("obs", "reward_next")
    elif np.dtype(schema.obs_dtype).kind == "f":
        finite = ("reward", "obs", "next_obs")
    else:
        finite = ("reward",)
    return _layout(specs, overlays, finite, rows)


def _batch_layout(obs_shape: tuple[int, ...], obs_dtype: str, rows: int) -> _Layout | None:
    obs = (rows, *obs_shape)
    specs = [("obs", obs_dtype, obs), ("action", "<i8", (rows,)), ("reward", "<f4", (rows,)),
             ("next_obs", obs_dtype, obs), ("terminated", "|u1", (rows,)), ("steps", "|u1", (rows,)),
             ("is_demo", "|u1", (rows,)), ("index", "<i8", (rows,)), ("weight", "<f4", (rows,))]
    return _layout(specs, [], (), rows)


def _cached_layout(kind: Kind, key: Any, suffix: str) -> _Layout | None:
    """The layout whose header text ends with ``suffix``, or None if ``suffix`` is not canonical
    for ``key`` (a schema, or an (obs_shape, obs_dtype) pair for batches)."""
    cache_key = (kind, key, suffix)
    layout = _LAYOUTS.get(cache_key)
    if layout is not None:
        return layout
    m = _ACTION_ROWS.search(suffix)
    if m is None or not 1 <= int(m.group(1)) <= MAX_BATCH_ROWS:
        return None
    rows = int(m.group(1))
    layout = (_transitions_layout(key, rows) if kind == Kind.TRANSITIONS else _batch_layout(*key, rows))
    if layout is None or layout.suffix != suffix:
        return None
    if len(_LAYOUTS) >= _MAX_LAYOUTS:  # many row counts (a hostile sender's): start over, stay bounded
        _LAYOUTS.clear()
    _LAYOUTS[cache_key] = layout
    return layout


def _fast_header(data: bytes | bytearray | memoryview, kind: Kind, key: Any
                 ) -> tuple[memoryview, int, dict, _Layout] | None:
    """Envelope, header and table of a canonical message: (buffer, where the arrays start, the header
    without its table, layout), or None (not canonical, or invalid)."""
    try:
        buf = memoryview(data).cast("B")
    except (TypeError, ValueError):
        return None
    n = len(buf)
    if not ENVELOPE.size <= n <= envelope.MAX_MESSAGE_BYTES:
        return None
    magic, version, got, reserved, hlen = ENVELOPE.unpack_from(buf, 0)
    end = ENVELOPE.size + hlen
    if (magic != MAGIC or version != WIRE_VERSION or got != kind or reserved != 0
            or not 2 <= hlen <= MAX_HEADER_BYTES or n < end):
        return None
    try:
        text = str(buf[ENVELOPE.size:end], "utf-8")
    except UnicodeDecodeError:
        return None
    cut = text.rfind(_ARRAYS_AT)
    if cut < 1:
        return None
    layout = _cached_layout(kind, key, text[cut:])
    if layout is None or n != end + layout.dtype.itemsize:
        return None
    try:
        header = HEADER_JSON.decode(text[:cut] + "}")
    except (ValueError, RecursionError):
        return None
    if type(header) is not dict or not header:
        return None
    return buf, end, header, layout


def _fields(buf: memoryview, end: int, layout: _Layout, copy: bool) -> np.ndarray:
    """A 0-d structured array over the message's array bytes: a view, or over one aligned copy."""
    if copy:
        return np.ndarray((), layout.dtype, np.frombuffer(buf, np.uint8, layout.dtype.itemsize, end).copy())
    return np.ndarray((), layout.dtype, buf, end)


# The ufuncs' reduce methods, called directly: ndarray.max()/min() go through a Python wrapper first.
_MAX, _MIN, _SUM = np.maximum.reduce, np.minimum.reduce, np.add.reduce


def _all_finite(arr: np.ndarray) -> bool:
    # A NaN or inf anywhere makes the sum NaN or inf, so a finite sum proves every value finite in
    # one reduction without a temporary array. A non-finite sum may also be an overflow of finite
    # values: then the exact check decides. (Such a sum, or +inf with -inf, makes numpy warn, once per
    # process under Python's default filter; an np.errstate here would cost every message 2 us.)
    return math.isfinite(_SUM(arr, axis=None)) or bool(np.isfinite(arr).all())


def fast_transitions(data: bytes | bytearray | memoryview, schema: TransitionSchema,
                      copy: bool) -> TransitionBatch | None:
    got = _fast_header(data, Kind.TRANSITIONS, schema)
    if got is None:
        return None
    buf, end, h, layout = got
    if copy and not layout.aligned:
        return None  # the generic path's separate copies are each aligned
    if not 1 <= layout.rows <= schema.max_rows:
        return None
    actor, extra = h.get("actor"), h.get("extra", {})
    seq, version, phase, steps = h.get("seq"), h.get("weights_version"), h.get("phase"), h.get("env_steps")
    if (type(actor) is not str or not NAME.fullmatch(actor) or type(extra) is not dict
            or type(seq) is not int or type(version) is not int or type(phase) is not int or type(steps) is not int
            or not (0 <= seq < MAX_COUNTER and 0 <= version < MAX_COUNTER and 0 <= phase < MAX_COUNTER
                    and 0 <= steps < MAX_COUNTER)):
        return None
    a = _fields(buf, end, layout, copy)
    if (_MAX(a["action_u"], None) >= schema.n_actions or _MAX(a["flags"], None) > 1 or _MIN(a["steps"], None) < 1
            or not all(_all_finite(a[name]) for name in layout.finite)):
        return None
    return TransitionBatch(actor=actor, seq=seq, weights_version=version, phase=phase, env_steps=steps,
                           obs=a["obs"], action=a["action"], reward=a["reward"], next_obs=a["next_obs"],
                           terminated=a["terminated"], truncated=a["truncated"], steps=a["steps"], extra=extra)


def fast_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch | None:
    got = _fast_header(data, Kind.BATCH, (schema.obs_shape, schema.obs_dtype))
    if got is None:
        return None
    buf, end, h, layout = got
    nb = h.get("num_batches")
    if not layout.aligned or type(nb) is not int or not 1 <= nb < MAX_COUNTER or layout.rows % nb:
        return None
    a = _fields(buf, end, layout, copy=True)  # the learner keeps (and may write) the arrays
    if _MIN(a["steps"], None) < 1:
        return None
    return SampledBatch(num_batches=nb, info=h.get("info", {}), **{k: a[k] for k in BATCH_FIELDS})


def fast_encode_batch(batch: SampledBatch) -> bytes | bytearray | None:
    """``encode_batch``'s bytes without the generic encoder's per-array copies: the header text is
    cached per shape, and each array is copied once, straight into the message. The arrays may be
    strided views (the replay server's are fields of the records it gathered). None unless every
    array has the canonical dtype and shape (then the generic encoder runs)."""
    arrays = [getattr(batch, k) for k in BATCH_FIELDS]
    obs = arrays[0]
    if not all(type(x) is np.ndarray for x in arrays) or obs.ndim < 1:
        return None
    rows = obs.shape[0]
    if not 1 <= rows <= MAX_BATCH_ROWS:
        return None
    key = (obs.shape[1:], obs.dtype.str)
    layout = _LAYOUTS.get((Kind.BATCH, key, rows))
    if layout is None:
        layout = _batch_layout(*key, rows)
        if layout is None:
            return None
        if len(_LAYOUTS) >= _MAX_LAYOUTS:
            _LAYOUTS.clear()
        _LAYOUTS[(Kind.BATCH, key, rows)] = layout
    fields = layout.dtype.fields
    if not all(x.dtype == fields[k][0].base and x.shape == fields[k][0].shape
               for k, x in zip(BATCH_FIELDS, arrays)):
        return None
    head = json.dumps({"num_batches": batch.num_batches, "info": batch.info}, separators=(",", ":"),
                      allow_nan=False)
    head_bytes = (head[:-1] + layout.suffix).encode()
    if len(head_bytes) > MAX_HEADER_BYTES:
        return None
    start = ENVELOPE.size + len(head_bytes)
    # One buffer with each array written into its place: no join of separate copies afterwards.
    # (A bytearray, which zenoh takes as a payload as readily as bytes.)
    message = bytearray(start + layout.dtype.itemsize)
    ENVELOPE.pack_into(message, 0, MAGIC, WIRE_VERSION, int(Kind.BATCH), 0, len(head_bytes))
    message[ENVELOPE.size:start] = head_bytes
    body = np.ndarray((), layout.dtype, message, start)
    for name, arr in zip(BATCH_FIELDS, arrays):
        body[name] = arr
    return message
