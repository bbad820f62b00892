"""Test helper, not a test file: network faults for ``tests/test_network_faults.py``.

* ``LinkProxy`` (``laneshift.deploy.linkproxy``, the run's own, which ``laneshift chaos`` uses too): a TCP proxy on 127.0.0.1 that forwards to one upstream (the run's zenoh
  router) and makes the link slow and jittery: every chunk read in either direction is delivered
  ``latency_s`` +- ``jitter_s`` later (uniform), in order (a TCP stream cannot be reordered, so a
  chunk never overtakes the one before it), and every ``reset_every_s`` (counted from the first
  client's connection) the oldest client connection is closed abruptly, so clients take turns
  (SO_LINGER 0: an RST to both the client and the upstream). Threads, bounded queues, every
  wait bounded; ``stop()`` closes everything it opened.
* ``learner_series(run_dir)``: the learner's ``(time, env_steps, updates)`` records from
  ``metrics.jsonl`` (``time`` is the wall clock of the learner's process: same machine, same clock).
* ``recovery_after(run_dir, t, steps_at_t)``: seconds from ``t`` to the first record whose env
  steps passed ``steps_at_t``.
* ``set_link(ns, dev, up)``: ``ip -n NS link set DEV up|down`` (inside a namespace the test made).

Room: tests, a helper the tests import or run. May import: laneshift (any floor), pytest, numpy, the
standard library and what the code under test needs.
"""

from __future__ import annotations

import contextlib
import json
import queue
import random
import socket
import struct
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from laneshift.deploy.linkproxy import LinkProxy, ProxyStats  # noqa: F401 - used by the tests


# ---------------------------------------------------------------------------- metrics.jsonl


def learner_series(run_dir: Path) -> list[tuple[float, int, int]]:
    """``(time, env_steps, updates)`` of every learner record in ``metrics.jsonl``, in file order."""
    try:
        lines = (Path(run_dir) / "metrics.jsonl").read_text().splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line being written
        if rec.get("kind") == "learner" and "env_steps" in rec and "time" in rec:
            out.append((float(rec["time"]), int(rec["env_steps"]), int(rec.get("updates", 0))))
    return out


def latest_env_steps(run_dir: Path) -> int:
    series = learner_series(run_dir)
    return series[-1][1] if series else 0


def recovery_after(run_dir: Path, t: float, steps_at_t: int) -> float | None:
    """Seconds from wall time ``t`` until the learner first logged more than ``steps_at_t`` env
    steps (stored transitions), or None if it never did."""
    for when, steps, _ in learner_series(run_dir):
        if when >= t and steps > steps_at_t:
            return round(when - t, 1)
    return None


def wait_env_steps(run_dir: Path, at_least: int, timeout_s: float, alive=lambda: True) -> int:
    """Poll ``metrics.jsonl`` until the learner logged ``at_least`` env steps (bounded); returns the last seen."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    for _ in range(int(timeout_s / 0.2) + 1):
        seen = latest_env_steps(run_dir)
        if seen >= at_least or time.monotonic() > deadline or not alive():
            break
        time.sleep(0.2)
    return seen


# ---------------------------------------------------------------------------- the link between namespaces


def set_link(ns: str, dev: str, up: bool) -> None:
    """Bring ``dev`` in namespace ``ns`` up or down (only namespaces a test made itself)."""
    subprocess.run(["ip", "-n", ns, "link", "set", "dev", dev, "up" if up else "down"], check=True,
                   capture_output=True, text=True, timeout=15)


