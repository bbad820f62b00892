"""Learner metrics: TensorBoard event files plus a JSON-lines log in the run dir.

- ``EventFile``: TensorBoard event records written in the caller's thread (tensorboardX's
  ``EventsWriter``), a failed write counted and the file abandoned, a new one tried later.
- ``MetricsLog``: ``<run dir>/tb`` (an ``EventFile``) and ``<run dir>/metrics.jsonl``, one line per
  record: ``{"kind", "step", "time", ...}``. ``step`` is the record's TensorBoard step: env steps
  for training records (the update count only in rehearsal / DQfD phase 1, which has no env
  steps). Other tools read ``kind``, ``env_steps``, ``updates`` and ``time`` from these lines.
  At the end of a run ``hparams`` writes the resolved config (``section.field``) with final
  metrics for TensorBoard's HParams dashboard, in ``<run dir>/tb/hparams``.

The greedy evaluation during training, whose results it also writes, is ``periodic_eval``.

Room: learner. May import: tensorboardX, numpy, the standard library.
"""

from __future__ import annotations

import json
import math
import numbers
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from tensorboardX.event_file_writer import EventsWriter
from tensorboardX.proto import event_pb2
from tensorboardX.summary import hparams as hparams_summaries
from tensorboardX.summary import scalar as scalar_summary
from tensorboardX.summary import text as text_summary


def _number(v: Any) -> float | None:
    """``v`` as a TensorBoard scalar, or None if it is not a number (None, strings, dicts)."""
    if isinstance(v, (bool, np.bool_)):
        return float(v)
    if isinstance(v, numbers.Real):
        return float(v)
    return None


class EventFile:
    """TensorBoard events appended to ``<logdir>/events.out.tfevents.*`` in the caller's thread.

    Why not tensorboardX's ``SummaryWriter``: its background thread dies on the first failed write
    (a full disk), and the next ``add_*`` then blocks for ever on the thread's full queue; that
    stalled the learner, and through the rate limiter the whole run (``laneshift chaos --faults
    disk-full``). Here a write that fails is counted (``failures``: events lost), the file is
    abandoned (a record may be cut short in it) and a new file is tried ``retry_s`` later, so
    events come back once there is room again. Flushed (with fsync, as tensorboardX does) at most
    every ``flush_s``; a few dozen small records a second cost the learner nothing measurable.
    """

    def __init__(self, logdir: Path, *, flush_s: float = 5.0, retry_s: float = 30.0,
                 clock: Any = time.monotonic):
        self.logdir, self.flush_s, self.retry_s, self.clock = Path(logdir), flush_s, retry_s, clock
        self.failures = 0
        self._events: EventsWriter | None = None
        self._retry_at = 0.0
        self._flush_at = 0.0

    def _file(self) -> EventsWriter | None:
        if self._events is None and self.clock() >= self._retry_at:
            try:
                self.logdir.mkdir(parents=True, exist_ok=True)
                # The suffix (nanoseconds): tensorboardX names files by the second and opens them
                # with "wb", so a learner restarted within the same second would empty the previous
                # one's file; nanoseconds keep the names in time order, TensorBoard's reading order.
                self._events = EventsWriter(str(self.logdir / "events"), f".{time.time_ns()}")
                self._flush_at = self.clock() + self.flush_s
            except OSError:
                self._retry_at = self.clock() + self.retry_s
        return self._events

    def add(self, summary: Any, step: int) -> None:
        """One ``Summary`` proto as an event at ``step``."""
        events = self._file()
        if events is None:
            self.failures += 1
            return
        try:
            events.write_event(event_pb2.Event(wall_time=time.time(), step=int(step), summary=summary))
            if self.clock() >= self._flush_at:
                events.flush()
                self._flush_at = self.clock() + self.flush_s
        except OSError:
            self.failures += 1
            self._abandon()

    def add_scalar(self, tag: str, value: float, step: int) -> None:
        self.add(scalar_summary(tag, value), step)

    def add_text(self, tag: str, text: str, step: int) -> None:
        self.add(text_summary(tag, text), step)

    def _abandon(self) -> None:
        events, self._events = self._events, None
        self._retry_at = self.clock() + self.retry_s
        if events is not None:
            try:
                events.close()
            except OSError:
                pass

    def close(self) -> None:
        if self._events is not None:
            try:
                self._events.close()
            except OSError:
                self.failures += 1
            self._events = None


class MetricsLog:
    def __init__(self, run_dir: str | Path):
        self.dir = Path(run_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.tb = EventFile(self.dir / "tb")
        self._jsonl = (self.dir / "metrics.jsonl").open("a", buffering=1)
        self.jsonl_failures = 0  # metrics.jsonl lines lost (a full or read-only run dir)

    @property
    def write_failures(self) -> int:
        """Records lost to failed writes: metrics.jsonl lines and TensorBoard events."""
        return self.jsonl_failures + self.tb.failures

    def write(self, kind: str, step: int, record: Mapping[str, Any],
              scalars: Mapping[str, Any] | None = None) -> None:
        """One JSON line ``{"kind", "step", "time", **record}`` and TensorBoard scalars at ``step``:
        ``scalars`` (tag -> value), or, when None, every number of ``record`` as ``<kind>/<key>``."""
        if scalars is None:
            scalars = {f"{kind}/{k}": v for k, v in record.items()}
        for tag, v in scalars.items():
            x = _number(v)
            if x is not None:
                self.tb.add_scalar(tag, x, step)
        try:
            self._jsonl.write(json.dumps({"kind": kind, "step": step, "time": time.time(), **record}) + "\n")
        except OSError:  # a full disk: the metrics line is lost (counted), training goes on
            self.jsonl_failures += 1

    def scalars(self, step: int, values: dict[str, float], kind: str = "learner") -> None:
        """``write(kind, step, values)``: every number as ``<kind>/<key>``."""
        self.write(kind, step, values)

    def config(self, config: dict) -> None:
        """The resolved config as text (TensorBoard's Text tab)."""
        self.tb.add_text("config", "```\n" + json.dumps(_jsonable(config), indent=2) + "\n```", 0)

    def hparams(self, config: Mapping[str, Mapping[str, Any]], metrics: Mapping[str, Any], step: int) -> None:
        """The config, flattened to ``section.field``, with the run's final ``metrics`` (tag ->
        number; None values are left out) for the HParams dashboard. Written to ``tb/hparams``: a
        resumed run writes there again, and TensorBoard shows the newest values."""
        hp = {f"{section}.{k}": _hparam_value(v) for section, body in config.items() for k, v in body.items()}
        final = {tag: x for tag, v in metrics.items() if (x := _number(v)) is not None}
        # SummaryWriter.add_hparams's three summaries, written as an EventFile (no writer thread).
        experiment, session_start, session_end = hparams_summaries(hp, final)
        events = EventFile(self.dir / "tb" / "hparams")
        for summary in (experiment, session_start, session_end):
            events.add(summary, 0)
        for tag, x in final.items():
            events.add_scalar(tag, x, step)
        events.close()
        self.tb.failures += events.failures

    def close(self) -> None:
        self.tb.close()
        try:
            self._jsonl.close()
        except OSError:
            self.jsonl_failures += 1


def _hparam_value(v: Any) -> bool | float | int | str:
    """HParams take numbers, strings and bools: lists become ``a,b``, maps JSON, inf / nan text."""
    if isinstance(v, bool) or isinstance(v, str):
        return v
    if isinstance(v, numbers.Real):
        return v if math.isfinite(v) else str(v)
    if isinstance(v, (list, tuple)):
        return ",".join(map(str, v))
    if v is None:
        return ""
    return json.dumps(_jsonable(v), sort_keys=True)


def _jsonable(v: Any) -> Any:
    """``v`` with non-finite floats as strings (``json.dumps`` would write bare ``Infinity``)."""
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if isinstance(v, Mapping):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    return v
