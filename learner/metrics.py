"""Learner metrics: TensorBoard event files plus a JSON-lines log in the run dir.

- ``MetricsLog``: ``<run dir>/tb`` (tensorboardX) and ``<run dir>/metrics.jsonl``, one line per
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
from tensorboardX import SummaryWriter
from tensorboardX.summary import hparams as hparams_summaries


def _number(v: Any) -> float | None:
    """``v`` as a TensorBoard scalar, or None if it is not a number (None, strings, dicts)."""
    if isinstance(v, (bool, np.bool_)):
        return float(v)
    if isinstance(v, numbers.Real):
        return float(v)
    return None


def _writer(logdir: Path, **kw: Any) -> SummaryWriter:
    """A SummaryWriter whose event file name cannot be another's: tensorboardX names files by the
    second and opens them with "wb", so a learner restarted (or resumed) within the same second
    would empty the previous one's file. The suffix (nanoseconds) keeps the names in time order,
    the order TensorBoard reads a directory's files in."""
    return SummaryWriter(str(logdir), filename_suffix=f".{time.time_ns()}", **kw)


class MetricsLog:
    def __init__(self, run_dir: str | Path):
        self.dir = Path(run_dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.tb = _writer(self.dir / "tb", flush_secs=5)
        self._jsonl = (self.dir / "metrics.jsonl").open("a", buffering=1)
        self.write_failures = 0

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
            self.write_failures += 1

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
        # SummaryWriter.add_hparams's own steps, with this module's event file names.
        experiment, session_start, session_end = hparams_summaries(hp, final)
        try:
            with _writer(self.dir / "tb" / "hparams") as w:
                for summary in (experiment, session_start, session_end):
                    w.file_writer.add_summary(summary)
                for tag, x in final.items():
                    w.add_scalar(tag, x, step)
        except OSError:
            self.write_failures += 1

    def close(self) -> None:
        self.tb.close()
        try:
            self._jsonl.close()
        except OSError:
            self.write_failures += 1


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
