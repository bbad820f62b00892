"""What the two replay benchmarks (``bench replay``, ``bench shards``) share: synthetic
TRANSITIONS messages encoded once and re-stamped per send (``synthetic_message``), waiting for a
router to listen and for child processes to be ready (``wait_ready``; a dead child is their error,
``check_alive``), stopping the publisher processes (``stop_publishers``), timing a call's latency, the sample batch they time and their error.

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import json
import signal
import socket
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from laneshift import wire

if TYPE_CHECKING:
    from laneshift.deploy.processes import ProcessGroup

SAMPLE_BATCH = 256  # rows of the sample requests both benches time

# Placeholders written by wire.encode_transitions, then overwritten in place with the real values
# padded by spaces to the same width (JSON allows whitespace after a number), so each message costs
# one join instead of a full encode. 16 digits, below the wire's 2**53 bound for header integers.
_SEQ_MARK = 1_111_111_111_111_111
_STEPS_MARK = 2_222_222_222_222_222
_MARK_WIDTH = 16


class BenchError(RuntimeError):
    """A replay benchmark could not measure (a child died, a server did not answer): its message says why."""


class PatchedMessage:
    """A pre-encoded TRANSITIONS message whose ``seq`` and ``env_steps`` can be rewritten cheaply."""

    def __init__(self, message: bytes):
        (hlen,) = struct.unpack_from("<I", message, 8)
        end = 12 + hlen
        marks = []
        for field, mark in (("seq", _SEQ_MARK), ("env_steps", _STEPS_MARK)):
            needle = f'"{field}":{mark}'.encode()
            pos = message.find(needle, 0, end)
            if pos < 0 or message.find(needle, pos + 1, end) >= 0:
                raise BenchError(f"placeholder for {field} not found exactly once in the header")
            marks.append((pos + len(needle) - _MARK_WIDTH, field))
        marks.sort()
        self.order = [f for _, f in marks]
        (a, _), (b, _) = marks
        self.pieces = (message[:a], message[a + _MARK_WIDTH:b], message[b + _MARK_WIDTH:])

    def build(self, seq: int, env_steps: int) -> bytes:
        vals = {"seq": seq, "env_steps": env_steps}
        p0, p1, p2 = self.pieces
        return b"".join((p0, b"%-16d" % vals[self.order[0]], p1, b"%-16d" % vals[self.order[1]], p2))


MESSAGES_PER_ACTOR = 4  # distinct messages a synthetic actor sends in turn (a frame table finds each new)


def synthetic_message(actor: str, schema: wire.TransitionSchema, rows: int,
                      rng: np.random.Generator) -> PatchedMessage:
    """Random but valid transitions for ``schema``, encoded once with placeholder counters."""
    shape = (rows, *schema.obs_shape)
    dtype = np.dtype(schema.obs_dtype)
    if dtype.kind == "f":
        obs = rng.standard_normal(shape).astype(dtype)
        next_obs = rng.standard_normal(shape).astype(dtype)
    elif len(schema.obs_shape) == 3:  # a frame-stacking env's stream: each item one new frame
        stack = schema.obs_shape[0]
        frames = rng.integers(0, 256, size=(rows + stack, *schema.obs_shape[1:]), dtype=np.uint8).astype(dtype)
        obs = np.stack([frames[i:i + stack] for i in range(rows)])
        next_obs = np.stack([frames[i + 1:i + 1 + stack] for i in range(rows)])
    else:
        obs = rng.integers(0, 256, size=shape, dtype=np.uint8).astype(dtype)
        next_obs = rng.integers(0, 256, size=shape, dtype=np.uint8).astype(dtype)
    batch = wire.TransitionBatch.from_arrays(
        actor=actor, seq=_SEQ_MARK, weights_version=0, phase=0, env_steps=_STEPS_MARK, obs=obs,
        action=rng.integers(0, schema.n_actions, size=rows), reward=rng.standard_normal(rows).astype(np.float32),
        next_obs=next_obs, terminated=(rng.random(rows) < 0.02).astype(np.uint8), truncated=np.zeros(rows, np.uint8))
    patcher = PatchedMessage(wire.encode_transitions(batch))
    check = wire.decode_transitions(patcher.build(7, 7 * rows), schema)  # the patched form is a valid message
    if check.seq != 7 or check.env_steps != 7 * rows or check.actor != actor:
        raise BenchError("patched message does not decode to the values written")
    return patcher


def wait_for_router(endpoint: str, check_alive: Callable[[], None], timeout_s: float = 60.0) -> None:
    """A zenoh client retries forever: make sure the router listens before opening a session."""
    host, port = endpoint.split("/", 1)[1].rsplit(":", 1)
    deadline = time.monotonic() + timeout_s
    while True:
        check_alive()
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise BenchError(f"the router did not listen on {endpoint} within {timeout_s:g} s") from None
            time.sleep(0.05)


def check_alive(group: ProcessGroup, names: list[str]) -> None:
    """A BenchError (with the end of its log) if one of the children ``names`` of ``group`` exited."""
    from laneshift.deploy.processes import ChildFailed

    try:
        group.check_alive(names)
    except ChildFailed as exc:
        raise BenchError(str(exc)) from None


def wait_ready(group: ProcessGroup, ready: dict[str, Path], timeout_s: float,
               on_failure: Callable[[], object] | None = None) -> None:
    """Wait until each child of ``group`` (name -> its ready file) has written its ready file. One
    that exits first, or is not ready within ``timeout_s``, is a BenchError (after ``on_failure``,
    which stops what is no longer wanted)."""
    from laneshift.deploy.processes import ChildFailed, wait_for_file

    try:
        for name, path in ready.items():
            wait_for_file(path, timeout_s, group, name)
    except ChildFailed as exc:
        if on_failure is not None:
            on_failure()
        raise BenchError(str(exc)) from None


def stop_publishers(group: ProcessGroup, pubs: list[dict]) -> dict[str, Any]:
    """Stop the publisher processes ``pubs`` (each ``{"name", "proc", "report", ...}``): SIGTERM to all
    at once, so they stop together, then each waited for (SIGKILL after 20 s). Returns each one's
    report, by name (None where it left none, or none that reads as JSON)."""
    for pub in pubs:
        if pub["proc"].poll() is None:
            pub["proc"].send_signal(signal.SIGTERM)
    reports: dict[str, Any] = {}
    for pub in pubs:
        group.stop(pub["name"], grace_s=20)
        try:
            reports[pub["name"]] = json.loads(pub["report"].read_text())
        except (OSError, ValueError):
            reports[pub["name"]] = None
    return reports


def time_calls(once: Callable[[], float], duration: float, warmup_n: int, min_n: int) -> dict:
    """``once()`` (which returns its own seconds) ``warmup_n`` times untimed, then for ``duration``
    seconds and at least ``min_n`` times: count, p50, p99, mean and max in ms."""
    for _ in range(warmup_n):
        once()
    times: list[float] = []
    end = time.perf_counter() + duration
    while time.perf_counter() < end or len(times) < min_n:
        times.append(once())
    ms = np.array(times) * 1e3
    return {"n": len(times), "p50_ms": round(float(np.percentile(ms, 50)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3), "mean_ms": round(float(ms.mean()), 3),
            "max_ms": round(float(ms.max()), 3)}
