"""The wire contract: every message format and zenoh key expression of laneshift.

This module imports only numpy and the standard library, so any process (or a client
written from ``docs/wire.md`` in another language) can speak the protocol. Nothing that
arrives over the network is ever unpickled: messages are a fixed binary envelope, a JSON
header and raw little-endian array bytes, validated field by field on decode.

Envelope (all integers little-endian)::

    offset  size  field
    0       4     magic b"LSHF"
    4       2     wire version (uint16) == WIRE_VERSION
    6       1     message kind (uint8), see Kind
    7       1     reserved, must be 0
    8       4     header length H (uint32), 2 <= H <= MAX_HEADER_BYTES
    12      H     UTF-8 JSON object: kind-specific fields + "arrays": [{"name","dtype","shape"}...]
    12+H    ...   the arrays' bytes, C order, in the order listed, no padding

The total length must equal ``12 + H + sum(array nbytes)`` exactly; weights messages carry a
safetensors blob as their single ``uint8`` array.

Example::

    >>> import numpy as np
    >>> schema = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=9)
    >>> batch = TransitionBatch.from_arrays(actor="w0", seq=0, weights_version=0, phase=0,
    ...     env_steps=2, obs=np.zeros((2, 3), np.float32), action=np.array([1, 2]),
    ...     reward=np.zeros(2, np.float32), next_obs=np.ones((2, 3), np.float32),
    ...     terminated=np.array([0, 1]), truncated=np.array([0, 0]))
    >>> decode_transitions(encode_transitions(batch), schema).action.tolist()
    [1, 2]

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

import enum
import json
import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .config import NAME  # the names rule: in config, which reads it without numpy

WIRE_VERSION = 2  # 2: transitions and batches carry `steps` (n-step returns)
MAGIC = b"LSHF"
_ENVELOPE = struct.Struct("<4sHBBI")  # magic, version, kind, reserved, header length
MAX_HEADER_BYTES = 64 * 1024
MAX_MESSAGE_BYTES = 256 * 1024 * 1024
MAX_BATCH_ROWS = 65536
# Dtypes allowed on the wire (numpy little-endian codes). Anything else is refused.
ALLOWED_DTYPES = {"|u1", "|b1", "|i1", "<i2", "<u2", "<i4", "<u4", "<i8", "<f2", "<f4", "<f8"}


class Kind(enum.IntEnum):
    """Message kinds; the byte at offset 6 of the envelope."""

    TRANSITIONS = 1  # actor -> replay server: a batch of transitions
    WEIGHTS = 2  # learner -> actors: safetensors blob + version
    SAMPLE_REQUEST = 3  # learner -> replay server (query payload)
    BATCH = 4  # replay server -> learner (query reply)
    ERROR = 5  # any reply that could not be served
    JSON = 6  # stats, episode statistics, control commands: header only
    PRIORITIES = 7  # learner -> replay server: new priorities of sampled items


class WireError(ValueError):
    """A message failed validation. ``reason`` is a short stable label for counters."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


# --------------------------------------------------------------------------- key expressions


#: A replay key namespace: the run's id, or ``<run>/shard-<i>`` for one shard of a sharded replay.
_REPLAY_NS = re.compile(r"^[A-Za-z0-9_\-]{1,64}/shard-[0-9]{1,3}$")


def _check_name(kind: str, value: str) -> str:
    if kind == "run" and isinstance(value, str) and _REPLAY_NS.fullmatch(value):
        return value
    if not isinstance(value, str) or not NAME.fullmatch(value):
        raise ValueError(f"{kind} {value!r} must match [A-Za-z0-9_-]{{1,64}}")
    return value


#: Replay shards a run may have (``replay.shards``).
MAX_SHARDS = 64


def replay_namespace(run: str, shard: int, shards: int) -> str:
    """What the replay keys of shard ``shard`` of ``shards`` are built from: the run id itself
    when there is one shard (a single replay server's keys are what they always were), else
    ``<run>/shard-<i>``, so ``sample_key(replay_namespace("r", 1, 2))`` is
    ``laneshift/r/shard-1/replay/sample``. The run-wide keys (weights, episodes, control,
    learner stats) always take the run id."""
    _check_name("run", run)
    if not 1 <= shards <= MAX_SHARDS or not 0 <= shard < shards:
        raise ValueError(f"shard {shard} of {shards}: need 0 <= shard < shards <= {MAX_SHARDS}")
    return run if shards == 1 else f"{run}/shard-{shard}"


_TRAILING_DIGITS = re.compile(r"([0-9]+)$")


def shard_of(actor: str, shards: int) -> int:
    """The replay shard an actor sends to: a stable function of its name alone, so a restarted
    actor finds its state (sequence numbers, env steps) on the same shard. A name ending in a
    number (the builder's ``w0``, ``w1``, ...) goes to that number modulo ``shards``, which spreads
    numbered actors evenly; any other name to its CRC-32 modulo ``shards``."""
    _check_name("actor", actor)
    if shards <= 1:
        return 0
    digits = _TRAILING_DIGITS.search(actor)
    return (int(digits.group(1)) if digits else zlib.crc32(actor.encode())) % shards


def transitions_key(run: str, actor: str) -> str:
    """Where actor ``actor`` publishes its transition batches."""
    return f"laneshift/{_check_name('run', run)}/transitions/{_check_name('actor', actor)}"


def transitions_wildcard(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/transitions/*"


def actor_from_transitions_key(key: str) -> str:
    """The actor name at the end of a transitions key (validated)."""
    return _check_name("actor", str(key).rsplit("/", 1)[-1])


def weights_key(run: str) -> str:
    """Learner publishes every new weights version here (subscribe for updates)."""
    return f"laneshift/{_check_name('run', run)}/weights"


def weights_latest_key(run: str) -> str:
    """Queryable answering with the latest weights (for late joiners and reconnects)."""
    return f"laneshift/{_check_name('run', run)}/weights/latest"


def sample_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/sample"


def replay_stats_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/stats"


def replay_control_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/replay/control"


def replay_info_key(run: str) -> str:
    """Queryable: JSON ``{"wire_version", "obs_shape", "obs_dtype", "n_actions", "run_id", "mode", "http_url"}``,
    what a client needs to build TRANSITIONS for this run (docs/wire.md §7)."""
    return f"laneshift/{_check_name('run', run)}/replay/info"


def priorities_key(run: str) -> str:
    """Learner -> replay server: PRIORITIES messages (prioritized sampling)."""
    return f"laneshift/{_check_name('run', run)}/replay/priorities"


def replay_flow_key(run: str) -> str:
    """Replay server -> actors: ``{"insert_ok": bool}``, whether the learner keeps up (rate limiter)."""
    return f"laneshift/{_check_name('run', run)}/replay/flow"


def episodes_key(run: str, actor: str) -> str:
    return f"laneshift/{_check_name('run', run)}/episodes/{_check_name('actor', actor)}"


def episodes_wildcard(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/episodes/*"


def learner_stats_key(run: str) -> str:
    return f"laneshift/{_check_name('run', run)}/learner/stats"


def control_key(run: str) -> str:
    """Run-wide control broadcast (e.g. ``{"cmd": "stop"}``)."""
    return f"laneshift/{_check_name('run', run)}/control"


# --------------------------------------------------------------------------- envelope


def _dtype_code(arr: np.ndarray) -> str:
    dt = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
    code = dt.str
    if code not in ALLOWED_DTYPES:
        raise ValueError(f"dtype {arr.dtype} cannot travel on the wire")
    return code


def encode(kind: Kind, header: Mapping[str, Any], arrays: Mapping[str, np.ndarray] | None = None) -> bytes:
    """Pack a message: envelope + JSON header (with the array table) + array bytes."""
    arrays = arrays or {}
    table, blobs = [], []
    for name, arr in arrays.items():
        arr = np.ascontiguousarray(arr).reshape(np.shape(arr))  # ascontiguousarray makes 0-d arrays 1-d
        code = _dtype_code(arr)
        arr = arr.astype(code, copy=False)
        table.append({"name": name, "dtype": code, "shape": list(arr.shape)})
        blobs.append(arr.tobytes())
    head = dict(header)
    head["arrays"] = table
    head_bytes = json.dumps(head, separators=(",", ":"), allow_nan=False).encode()
    if len(head_bytes) > MAX_HEADER_BYTES:
        raise ValueError(f"header of {len(head_bytes)} bytes exceeds {MAX_HEADER_BYTES}")
    return b"".join([_ENVELOPE.pack(MAGIC, WIRE_VERSION, int(kind), 0, len(head_bytes)), head_bytes, *blobs])


@dataclass(frozen=True)
class Message:
    kind: Kind
    header: dict
    arrays: dict[str, np.ndarray]


def decode(data: bytes | bytearray | memoryview, expect: Kind | None = None) -> Message:
    """Parse and validate the envelope and array table. Raises WireError(reason, detail)."""
    buf = memoryview(data).cast("B")
    if len(buf) > MAX_MESSAGE_BYTES:
        raise WireError("oversized", f"{len(buf)} bytes > {MAX_MESSAGE_BYTES}")
    if len(buf) < _ENVELOPE.size:
        raise WireError("truncated", f"{len(buf)} bytes is shorter than the {_ENVELOPE.size}-byte envelope")
    magic, version, kind, reserved, hlen = _ENVELOPE.unpack_from(buf, 0)
    if magic != MAGIC:
        raise WireError("bad_magic", f"magic {bytes(magic)!r} != {MAGIC!r}")
    if version != WIRE_VERSION:
        raise WireError("wrong_version", f"wire version {version}, this build speaks {WIRE_VERSION}")
    try:
        kind = Kind(kind)
    except ValueError:
        raise WireError("bad_kind", f"unknown message kind {kind}") from None
    if expect is not None and kind != expect:
        raise WireError("wrong_kind", f"expected {expect.name}, got {kind.name}")
    if reserved != 0:
        raise WireError("bad_envelope", "reserved byte is not 0")
    if not 2 <= hlen <= MAX_HEADER_BYTES:
        raise WireError("bad_header", f"header length {hlen} out of range")
    end = _ENVELOPE.size + hlen
    if len(buf) < end:
        raise WireError("truncated", f"header needs {end} bytes, message has {len(buf)}")
    try:
        header = _HEADER_JSON.decode(bytes(buf[_ENVELOPE.size:end]).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError, RecursionError) as exc:
        raise WireError("bad_header", f"header is not valid JSON: {exc}") from None
    if not isinstance(header, dict) or not isinstance(header.get("arrays"), list):
        raise WireError("bad_header", "header must be an object with an 'arrays' list")
    arrays: dict[str, np.ndarray] = {}
    offset = end
    for spec in header.pop("arrays"):
        name, arr, offset = _read_array(buf, spec, offset)
        if name in arrays:
            raise WireError("bad_header", f"array {name!r} listed twice")
        arrays[name] = arr
    if offset != len(buf):
        raise WireError("trailing_bytes" if offset < len(buf) else "truncated",
                        f"arrays end at byte {offset}, message has {len(buf)}")
    return Message(kind, header, arrays)


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not allowed in headers")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text[:20]} overflows to infinity")
    return value


# One decoder for every header: ``json.loads(..., parse_constant=, parse_float=)`` builds a new
# JSONDecoder (and its scanner) per call, 6 us of a 32-row TRANSITIONS decode. Sharing it between
# threads is safe: the scanner keeps no state across calls but a key-interning memo, cleared after each.
_HEADER_JSON = json.JSONDecoder(parse_constant=_reject_constant, parse_float=_finite_float)


def _read_array(buf: memoryview, spec: Any, offset: int) -> tuple[str, np.ndarray, int]:
    if not isinstance(spec, dict) or set(spec) != {"name", "dtype", "shape"}:
        raise WireError("bad_header", f"array entry {spec!r} must have exactly name, dtype, shape")
    name, code, shape = spec["name"], spec["dtype"], spec["shape"]
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise WireError("bad_header", f"bad array name {name!r}")
    if not isinstance(code, str) or code not in ALLOWED_DTYPES:
        raise WireError("bad_dtype", f"array {name!r}: dtype {code!r} not allowed")
    if (not isinstance(shape, list) or len(shape) > 8
            or not all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d < 2**31 for d in shape)):
        raise WireError("bad_shape", f"array {name!r}: bad shape {shape!r}")
    dtype = np.dtype(code)
    nbytes = math.prod(shape) * dtype.itemsize
    if offset + nbytes > len(buf):
        raise WireError("truncated", f"array {name!r} needs {nbytes} bytes at {offset}, message has {len(buf)}")
    # Copy out of the network buffer: the caller may keep the array after zenoh reuses it.
    arr = np.frombuffer(buf, dtype=dtype, count=math.prod(shape), offset=offset).reshape(shape).copy()
    return name, arr, offset + nbytes


MAX_COUNTER = 2**53  # header integers stay exact in any JSON implementation


def _require(header: dict, name: str, typ: type | tuple, reason: str = "bad_header") -> Any:
    value = header.get(name)
    if not isinstance(value, typ) or isinstance(value, bool) and typ is not bool:
        raise WireError(reason, f"header field {name!r} must be {getattr(typ, '__name__', typ)}, got {value!r}")
    if typ is int and not -MAX_COUNTER < value < MAX_COUNTER:
        raise WireError(reason, f"header field {name!r} out of range: {value}")
    return value


# --------------------------------------------------------------------------- transitions


@dataclass(frozen=True)
class TransitionSchema:
    """What a run's transitions look like; the replay server validates every batch against it."""

    obs_shape: tuple[int, ...]
    obs_dtype: str
    n_actions: int
    max_rows: int = MAX_BATCH_ROWS

    def __post_init__(self) -> None:
        object.__setattr__(self, "obs_shape", tuple(int(d) for d in self.obs_shape))
        object.__setattr__(self, "obs_dtype", np.dtype(self.obs_dtype).str)


@dataclass(frozen=True)
class TransitionBatch:
    """B transitions from one actor, produced under one weights version."""

    actor: str
    seq: int  # per-actor message counter, starts at 0
    weights_version: int  # the weights version that chose these actions
    phase: int  # rehearsal phase the actor was in (0 when not rehearsing)
    env_steps: int  # the actor's cumulative env steps after this batch
    obs: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    # Rewards summed in `reward` (n-step returns, laneshift.nstep): the learner discounts the
    # bootstrap value at next_obs by gamma ** steps. 1 for ordinary transitions.
    steps: np.ndarray | None = None
    extra: dict = field(default_factory=dict)  # free-form JSON fields (e.g. episode ids)

    def __post_init__(self) -> None:
        if self.steps is None:
            object.__setattr__(self, "steps", np.ones(len(self), np.uint8))

    @classmethod
    def from_arrays(cls, **kw: Any) -> "TransitionBatch":
        kw["action"] = np.asarray(kw["action"], dtype=np.int64)
        kw["reward"] = np.asarray(kw["reward"], dtype=np.float32)
        kw["terminated"] = np.asarray(kw["terminated"], dtype=np.uint8)
        kw["truncated"] = np.asarray(kw["truncated"], dtype=np.uint8)
        if kw.get("steps") is not None:
            kw["steps"] = np.asarray(kw["steps"], dtype=np.uint8)
        return cls(**kw)

    def __len__(self) -> int:
        return int(self.action.shape[0])


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

    A message in the form ``encode_transitions`` writes takes a fast path (``_fast_transitions``); any
    other form, and anything invalid, goes through the generic checks below, which name the reason.
    """
    batch = _fast_transitions(data, schema, copy)
    return batch if batch is not None else _checked_transitions(data, schema)


def _checked_transitions(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> TransitionBatch:
    msg = decode(data, expect=Kind.TRANSITIONS)
    h = msg.header
    actor = _require(h, "actor", str)
    if not NAME.fullmatch(actor):
        raise WireError("bad_header", f"bad actor name {actor!r}")
    ints = {k: _require(h, k, int) for k in ("seq", "weights_version", "phase", "env_steps")}
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


# --------------------------------------------------------------------------- fast paths (canonical form)
#
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
    if not _ENVELOPE.size <= n <= MAX_MESSAGE_BYTES:
        return None
    magic, version, got, reserved, hlen = _ENVELOPE.unpack_from(buf, 0)
    end = _ENVELOPE.size + hlen
    if (magic != MAGIC or version != WIRE_VERSION or got != kind or reserved != 0
            or not 2 <= hlen <= MAX_HEADER_BYTES or n < end):
        return None
    try:
        text = str(buf[_ENVELOPE.size:end], "utf-8")
    except UnicodeDecodeError:
        return None
    cut = text.rfind(_ARRAYS_AT)
    if cut < 1:
        return None
    layout = _cached_layout(kind, key, text[cut:])
    if layout is None or n != end + layout.dtype.itemsize:
        return None
    try:
        header = _HEADER_JSON.decode(text[:cut] + "}")
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


def _fast_transitions(data: bytes | bytearray | memoryview, schema: TransitionSchema,
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


def _fast_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch | None:
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
    return SampledBatch(num_batches=nb, info=h.get("info", {}), **{k: a[k] for k in _BATCH_FIELDS})


def _fast_encode_batch(batch: SampledBatch) -> bytes | bytearray | None:
    """``encode_batch``'s bytes without the generic encoder's per-array copies: the header text is
    cached per shape, and each array is copied once, straight into the message. The arrays may be
    strided views (the replay server's are fields of the records it gathered). None unless every
    array has the canonical dtype and shape (then the generic encoder runs)."""
    arrays = [getattr(batch, k) for k in _BATCH_FIELDS]
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
               for k, x in zip(_BATCH_FIELDS, arrays)):
        return None
    head = json.dumps({"num_batches": batch.num_batches, "info": batch.info}, separators=(",", ":"),
                      allow_nan=False)
    head_bytes = (head[:-1] + layout.suffix).encode()
    if len(head_bytes) > MAX_HEADER_BYTES:
        return None
    start = _ENVELOPE.size + len(head_bytes)
    # One buffer with each array written into its place: no join of separate copies afterwards.
    # (A bytearray, which zenoh takes as a payload as readily as bytes.)
    message = bytearray(start + layout.dtype.itemsize)
    _ENVELOPE.pack_into(message, 0, MAGIC, WIRE_VERSION, int(Kind.BATCH), 0, len(head_bytes))
    message[_ENVELOPE.size:start] = head_bytes
    body = np.ndarray((), layout.dtype, message, start)
    for name, arr in zip(_BATCH_FIELDS, arrays):
        body[name] = arr
    return message


# --------------------------------------------------------------------------- weights (safetensors)

_ST_DTYPES = {"F64": "<f8", "F32": "<f4", "F16": "<f2", "I64": "<i8", "I32": "<i4", "I16": "<i2",
              "I8": "|i1", "U8": "|u1", "U16": "<u2", "U32": "<u4", "BOOL": "|b1"}
_ST_CODES = {v: k for k, v in _ST_DTYPES.items()}


def safetensors_dumps(tensors: Mapping[str, np.ndarray], metadata: Mapping[str, str] | None = None) -> bytes:
    """Serialise arrays in the safetensors format (``safetensors.numpy.load`` reads it, and vice
    versa; tests/test_wire.py checks both ways and that the bytes equal the package's own).

    Written here rather than with ``safetensors.numpy.save``, which makes the same bytes but
    slower: 2.6-3.8 ms against 0.17-0.33 ms for 1 MB of float32 (4 x 256 x 256, measured here
    side by side), paid on every weights broadcast."""
    header: dict[str, Any] = {}
    if metadata:
        header["__metadata__"] = {str(k): str(v) for k, v in metadata.items()}
    blobs, offset = [], 0
    for name in sorted(tensors):
        arr = np.ascontiguousarray(tensors[name]).reshape(np.shape(tensors[name]))
        code = _dtype_code(arr)
        raw = arr.astype(code, copy=False).tobytes()
        header[name] = {"dtype": _ST_CODES[code], "shape": list(arr.shape), "data_offsets": [offset, offset + len(raw)]}
        blobs.append(raw)
        offset += len(raw)
    head = json.dumps(header, separators=(",", ":")).encode()
    head += b" " * (-len(head) % 8)  # the format pads the header to 8-byte alignment
    return b"".join([struct.pack("<Q", len(head)), head, *blobs])


def safetensors_loads(data: bytes | bytearray | memoryview) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """Parse a safetensors blob into numpy arrays, validating every offset. Raises WireError.

    Written here rather than with ``safetensors.numpy.load``: that returns no metadata (the
    weights' version; ``safe_open``, which does, reads files only), and a blob from the network is
    refused before any allocation with the reason the wire reports (``bad_weights``), its header
    size bounded."""
    buf = memoryview(data).cast("B")
    if len(buf) < 8:
        raise WireError("bad_weights", "safetensors blob shorter than 8 bytes")
    (hlen,) = struct.unpack_from("<Q", buf, 0)
    if hlen > min(MAX_HEADER_BYTES * 16, len(buf) - 8):
        raise WireError("bad_weights", f"safetensors header length {hlen} out of range")
    try:
        header = json.loads(bytes(buf[8:8 + hlen]).decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise WireError("bad_weights", f"safetensors header is not JSON: {exc}") from None
    if not isinstance(header, dict):
        raise WireError("bad_weights", "safetensors header is not an object")
    meta = header.pop("__metadata__", {}) or {}
    if not isinstance(meta, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in meta.items()):
        raise WireError("bad_weights", "safetensors __metadata__ must map strings to strings")
    data_start, data_len = 8 + hlen, len(buf) - 8 - hlen
    tensors, spans = {}, []
    for name, spec in header.items():
        try:
            code = _ST_DTYPES[spec["dtype"]]
            shape = [int(d) for d in spec["shape"]]
            begin, stop = (int(x) for x in spec["data_offsets"])
        except (KeyError, TypeError, ValueError):
            raise WireError("bad_weights", f"tensor {name!r}: bad entry {spec!r}") from None
        nbytes = math.prod(shape) * np.dtype(code).itemsize
        if any(d < 0 for d in shape) or not 0 <= begin <= stop <= data_len or stop - begin != nbytes:
            raise WireError("bad_weights", f"tensor {name!r}: offsets {begin}..{stop} do not fit shape {shape}")
        arr = np.frombuffer(buf, dtype=code, count=math.prod(shape), offset=data_start + begin).reshape(shape).copy()
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise WireError("non_finite", f"tensor {name!r} contains NaN or inf")
        tensors[name] = arr
        spans.append((begin, stop))
    spans.sort()
    if any(a[1] > b[0] for a, b in zip(spans, spans[1:])):
        raise WireError("bad_weights", "tensors overlap")
    return tensors, dict(meta)


@dataclass(frozen=True)
class Weights:
    version: int  # strictly increasing per run
    phase: int  # rehearsal phase (0 when not rehearsing)
    updates: int  # learner updates done when these weights were taken
    tensors: dict[str, np.ndarray]


def tensors_digest(tensors: Mapping[str, np.ndarray]) -> str:
    """sha256 over names and bytes in name order: equal digests mean equal weights."""
    import hashlib

    h = hashlib.sha256()
    for name in sorted(tensors):
        h.update(name.encode())
        h.update(np.ascontiguousarray(tensors[name]).tobytes())
    return h.hexdigest()


def encode_weights(weights: Weights) -> bytes:
    blob = safetensors_dumps(weights.tensors, {"version": str(weights.version)})
    header = {"version": int(weights.version), "phase": int(weights.phase), "updates": int(weights.updates)}
    return encode(Kind.WEIGHTS, header, {"safetensors": np.frombuffer(blob, np.uint8)})


def decode_weights(data: bytes | bytearray | memoryview) -> Weights:
    msg = decode(data, expect=Kind.WEIGHTS)
    ints = {k: _require(msg.header, k, int) for k in ("version", "phase", "updates")}
    if ints["version"] < 0:
        raise WireError("bad_header", "negative weights version")
    blob = msg.arrays.get("safetensors")
    if set(msg.arrays) != {"safetensors"} or blob.ndim != 1 or blob.dtype.str != "|u1":
        raise WireError("bad_arrays", "weights carry exactly one 1-D uint8 array 'safetensors'")
    tensors, _ = safetensors_loads(msg.arrays["safetensors"].tobytes())
    return Weights(tensors=tensors, **ints)


# --------------------------------------------------------------------------- sampling


@dataclass(frozen=True)
class SampleRequest:
    batch_size: int
    num_batches: int = 1
    # Sync parallel mode: serve only once every listed actor delivered a batch made with
    # weights version >= min_version (the MATLAB "host waits for every worker").
    min_version: int = -1
    actors: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not 1 <= self.batch_size <= MAX_BATCH_ROWS or not 1 <= self.num_batches <= 64:
            raise WireError("bad_request", f"batch_size {self.batch_size} / num_batches {self.num_batches} out of range")
        if self.batch_size * self.num_batches > MAX_BATCH_ROWS:
            raise WireError("bad_request", "batch_size * num_batches too large")


def encode_sample_request(req: SampleRequest) -> bytes:
    return encode(Kind.SAMPLE_REQUEST, {"batch_size": req.batch_size, "num_batches": req.num_batches,
                                        "min_version": req.min_version, "actors": list(req.actors)})


def decode_sample_request(data: bytes | bytearray | memoryview) -> SampleRequest:
    msg = decode(data, expect=Kind.SAMPLE_REQUEST)
    h = msg.header
    actors = h.get("actors", [])
    if not isinstance(actors, list) or not all(isinstance(x, str) and NAME.fullmatch(x) for x in actors):
        raise WireError("bad_request", f"bad actors list {actors!r}")
    return SampleRequest(batch_size=_require(h, "batch_size", int, "bad_request"),
                         num_batches=_require(h, "num_batches", int, "bad_request"),
                         min_version=_require(h, "min_version", int, "bad_request"), actors=tuple(actors))


@dataclass(frozen=True)
class SampledBatch:
    """``num_batches * batch_size`` rows; split with ``np.split(..., num_batches)``."""

    obs: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    steps: np.ndarray  # rewards summed per row: the bootstrap is discounted by gamma ** steps
    is_demo: np.ndarray  # 1 where the row came from the demo shard
    index: np.ndarray  # item keys, for priority updates
    weight: np.ndarray  # importance-sampling weights (1 for uniform sampling)
    num_batches: int = 1
    info: dict = field(default_factory=dict)


_BATCH_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "steps", "is_demo", "index", "weight")


def encode_batch(batch: SampledBatch) -> bytes | bytearray:
    fast = _fast_encode_batch(batch)  # the same bytes, fewer copies
    if fast is not None:
        return fast
    return encode(Kind.BATCH, {"num_batches": batch.num_batches, "info": batch.info},
                  {k: getattr(batch, k) for k in _BATCH_FIELDS})


def decode_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch:
    """Decode and validate a BATCH reply (arrays: one private copy); raises WireError. The form
    ``encode_batch`` writes takes a fast path (see ``_fast_transitions``), the rest the generic one."""
    batch = _fast_batch(data, schema)
    return batch if batch is not None else _checked_batch(data, schema)


def _checked_batch(data: bytes | bytearray | memoryview, schema: TransitionSchema) -> SampledBatch:
    msg = decode(data, expect=Kind.BATCH)
    if set(msg.arrays) != set(_BATCH_FIELDS):
        raise WireError("bad_arrays", f"batch arrays {sorted(msg.arrays)}")
    if msg.arrays["action"].ndim != 1:
        raise WireError("bad_shape", f"batch action must be 1-D, got shape {msg.arrays['action'].shape}")
    rows = msg.arrays["action"].shape[0]
    for name in ("obs", "next_obs"):
        if msg.arrays[name].shape != (rows, *schema.obs_shape) or msg.arrays[name].dtype.str != schema.obs_dtype:
            raise WireError("bad_shape", f"batch {name} {msg.arrays[name].shape} does not fit the schema")
    for name in _BATCH_FIELDS[1:]:
        if name not in ("next_obs",) and msg.arrays[name].shape != (rows,):
            raise WireError("bad_shape", f"batch {name} shape {msg.arrays[name].shape}")
    steps = msg.arrays["steps"]
    if steps.dtype.str != "|u1" or (rows and steps.min() < 1):
        raise WireError("bad_value", "batch steps must be uint8 >= 1")
    nb = _require(msg.header, "num_batches", int)
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


# --------------------------------------------------------------------------- JSON messages and errors


def encode_json(body: Mapping[str, Any]) -> bytes:
    """Stats, episode records and control commands: a header-only message."""
    return encode(Kind.JSON, {"body": dict(body)})


def decode_json(data: bytes | bytearray | memoryview) -> dict:
    msg = decode(data, expect=Kind.JSON)
    body = msg.header.get("body")
    if not isinstance(body, dict) or msg.arrays:
        raise WireError("bad_header", "JSON message needs an object 'body' and no arrays")
    return body


@dataclass(frozen=True)
class EpisodeRecord:
    """An env worker's record of one finished episode (``episodes/<actor>``, a JSON message).
    ``return`` and ``length`` are required; the rest default as an older sender leaves them."""

    actor: str
    return_: float  # "return" on the wire
    length: int
    crashed: bool = False
    on_target_lane: bool = False
    weights_version: int = 0
    phase: int = 0
    env_steps: int = 0  # the actor's env steps at the episode's end
    epsilon: float = 0.0


def encode_episode(rec: EpisodeRecord) -> bytes:
    return encode_json({"actor": rec.actor, "return": float(rec.return_), "length": int(rec.length),
                        "crashed": bool(rec.crashed), "on_target_lane": bool(rec.on_target_lane),
                        "weights_version": int(rec.weights_version), "phase": int(rec.phase),
                        "env_steps": int(rec.env_steps), "epsilon": float(rec.epsilon)})


def decode_episode(data: bytes | bytearray | memoryview) -> EpisodeRecord:
    """Validated: WireError (``bad_value``) names the first field that is missing or of the wrong
    type, a non-finite return or epsilon, or a negative count."""
    body = decode_json(data)

    def field_of(name: str, kind: type, default: Any = None) -> Any:
        value = body.get(name, default)
        if value is None:
            raise WireError("bad_value", f"episode record: {name!r} is required")
        accepted = (int, float) if kind is float else kind  # a JSON number may come without a point
        if not isinstance(value, accepted) or isinstance(value, bool) and kind is not bool:  # as _require
            raise WireError("bad_value", f"episode record: {name!r} must be {kind.__name__}, got {value!r}")
        if kind is float and not math.isfinite(value):
            raise WireError("bad_value", f"episode record: {name!r} must be finite, got {value!r}")
        if kind is int and value < 0:
            raise WireError("bad_value", f"episode record: {name!r} must be >= 0, got {value!r}")
        return value

    return EpisodeRecord(actor=field_of("actor", str, ""), return_=float(field_of("return", float)),
                         length=field_of("length", int), crashed=field_of("crashed", bool, False),
                         on_target_lane=field_of("on_target_lane", bool, False),
                         weights_version=field_of("weights_version", int, 0), phase=field_of("phase", int, 0),
                         env_steps=field_of("env_steps", int, 0), epsilon=float(field_of("epsilon", float, 0.0)))


def encode_error(reason: str, detail: str = "", retry_after_ms: int = 0) -> bytes:
    return encode(Kind.ERROR, {"reason": reason, "detail": detail, "retry_after_ms": int(retry_after_ms)})


def peek_kind(data: bytes | bytearray | memoryview) -> Kind | None:
    """The kind byte of a message, or None if the envelope is unreadable (no validation)."""
    buf = memoryview(data).cast("B")
    if len(buf) < _ENVELOPE.size or bytes(buf[:4]) != MAGIC:
        return None
    try:
        return Kind(buf[6])
    except ValueError:
        return None


def decode_error(data: bytes | bytearray | memoryview) -> WireError:
    msg = decode(data, expect=Kind.ERROR)
    err = WireError(str(msg.header.get("reason", "error")), str(msg.header.get("detail", "")))
    retry = msg.header.get("retry_after_ms", 0)
    if not isinstance(retry, int) or isinstance(retry, bool) or not 0 <= retry <= 60_000:
        raise WireError("bad_header", f"retry_after_ms must be an integer in [0, 60000], got {retry!r}")
    err.retry_after_ms = retry  # type: ignore[attr-defined]
    return err
