"""The wire's envelope: the fixed binary frame every message travels in, its limits, the message
kinds, and the generic encoder and validating decoder the message codecs build on.

Envelope (all integers little-endian)::

    offset  size  field
    0       4     magic b"LSHF"
    4       2     wire version (uint16) == WIRE_VERSION
    6       1     message kind (uint8), see Kind
    7       1     reserved, must be 0
    8       4     header length H (uint32), 2 <= H <= MAX_HEADER_BYTES
    12      H     UTF-8 JSON object: kind-specific fields + "arrays": [{"name","dtype","shape"}...]
    12+H    ...   the arrays' bytes, C order, in the order listed, no padding

The total length must equal ``12 + H + sum(array nbytes)`` exactly.

Room: the contract (shared by every process). May import: numpy, the standard library,
``laneshift.config`` (the name rule) and ``.errors``; no other module of the wire package.
"""

from __future__ import annotations

import enum
import json
import math
import struct
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..config import NAME  # the names rule: in config, which reads it without numpy
from .errors import WireError

WIRE_VERSION = 2  # 2: transitions and batches carry `steps` (n-step returns)
MAGIC = b"LSHF"
ENVELOPE = struct.Struct("<4sHBBI")  # magic, version, kind, reserved, header length
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


# --------------------------------------------------------------------------- encode and decode


def dtype_code(arr: np.ndarray) -> str:
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
        code = dtype_code(arr)
        arr = arr.astype(code, copy=False)
        table.append({"name": name, "dtype": code, "shape": list(arr.shape)})
        blobs.append(arr.tobytes())
    head = dict(header)
    head["arrays"] = table
    head_bytes = json.dumps(head, separators=(",", ":"), allow_nan=False).encode()
    if len(head_bytes) > MAX_HEADER_BYTES:
        raise ValueError(f"header of {len(head_bytes)} bytes exceeds {MAX_HEADER_BYTES}")
    return b"".join([ENVELOPE.pack(MAGIC, WIRE_VERSION, int(kind), 0, len(head_bytes)), head_bytes, *blobs])


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
    if len(buf) < ENVELOPE.size:
        raise WireError("truncated", f"{len(buf)} bytes is shorter than the {ENVELOPE.size}-byte envelope")
    magic, version, kind, reserved, hlen = ENVELOPE.unpack_from(buf, 0)
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
    end = ENVELOPE.size + hlen
    if len(buf) < end:
        raise WireError("truncated", f"header needs {end} bytes, message has {len(buf)}")
    try:
        header = HEADER_JSON.decode(bytes(buf[ENVELOPE.size:end]).decode("utf-8"))
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
HEADER_JSON = json.JSONDecoder(parse_constant=_reject_constant, parse_float=_finite_float)



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


def require_field(header: dict, name: str, typ: type | tuple, reason: str = "bad_header") -> Any:
    value = header.get(name)
    if not isinstance(value, typ) or isinstance(value, bool) and typ is not bool:
        raise WireError(reason, f"header field {name!r} must be {getattr(typ, '__name__', typ)}, got {value!r}")
    if typ is int and not -MAX_COUNTER < value < MAX_COUNTER:
        raise WireError(reason, f"header field {name!r} out of range: {value}")
    return value


def peek_kind(data: bytes | bytearray | memoryview) -> Kind | None:
    """The kind byte of a message, or None if the envelope is unreadable (no validation)."""
    buf = memoryview(data).cast("B")
    if len(buf) < ENVELOPE.size or bytes(buf[:4]) != MAGIC:
        return None
    try:
        return Kind(buf[6])
    except ValueError:
        return None
