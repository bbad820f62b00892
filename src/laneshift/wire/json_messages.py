"""The header-only messages: JSON bodies (stats, control commands), an env worker's episode records
(``episodes/<actor>``) and ERROR replies (a reason, a detail, a retry hint).

Room: the contract (shared by every process). May import: the standard library, ``.errors`` and
``.envelope``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from .envelope import Kind, decode, encode
from .errors import WireError


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
        if not isinstance(value, accepted) or isinstance(value, bool) and kind is not bool:  # as require_field
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


def decode_error(data: bytes | bytearray | memoryview) -> WireError:
    msg = decode(data, expect=Kind.ERROR)
    err = WireError(str(msg.header.get("reason", "error")), str(msg.header.get("detail", "")))
    retry = msg.header.get("retry_after_ms", 0)
    if not isinstance(retry, int) or isinstance(retry, bool) or not 0 <= retry <= 60_000:
        raise WireError("bad_header", f"retry_after_ms must be an integer in [0, 60000], got {retry!r}")
    err.retry_after_ms = retry  # type: ignore[attr-defined]
    return err
