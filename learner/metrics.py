"""Learner metrics: TensorBoard event files plus a JSON-lines log in the run dir, and the greedy
evaluation that runs during training.

- ``MetricsLog``: ``<run dir>/tb`` (tensorboardX) and ``<run dir>/metrics.jsonl``, one line per
  record: ``{"kind", "step", "time", ...}``. ``step`` is the record's TensorBoard step: env steps
  for training records (the update count only in rehearsal / DQfD phase 1, which has no env
  steps). Other tools read ``kind``, ``env_steps``, ``updates`` and ``time`` from these lines.
  At the end of a run ``hparams`` writes the resolved config (``section.field``) with final
  metrics for TensorBoard's HParams dashboard, in ``<run dir>/tb/hparams``.
- ``GreedyEval``: ``train.eval_every`` / ``train.periodic_eval_episodes``: a copy of the network
  the run hands out (``DoubleDQN.policy_net``) played greedily on a background thread, by the ``EvaluatePolicy`` the builder hands
  the learner (``laneshift.actors.evaluation``: the learner never imports the simulator itself).

Room: learner. May import: tensorboardX, torch, numpy, the contract (``laneshift.config``,
``laneshift.qnet``).
"""

from __future__ import annotations

import json
import math
import numbers
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tensorboardX import SummaryWriter
from tensorboardX.summary import hparams as hparams_summaries

from laneshift.qnet import build_q_network

#: A network's greedy policy over rows of observations (rows -> one action each).
BatchPolicy = Callable[[np.ndarray], np.ndarray]
#: The seam to the env-running side: play ``policy`` greedily for a fixed set of episodes (the
#: builder binds the env, the episode count and the seeds, and drives the ego vehicle and any
#: policy vehicles with it) and return the rates (``survival_rate``, ``achievement_rate``,
#: ``return_mean``, ...).
EvaluatePolicy = Callable[[BatchPolicy], dict]


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


# ---------------------------------------------------------------------------- evaluation during training


class _Cancelled(Exception):
    pass


class GreedyEval:
    """Greedy episodes of a snapshot of the network the run hands out, on a background thread.

    ``start`` copies the weights to CPU (the only work on the learner's thread); the thread builds
    its own network and hands its greedy policy over rows (``BatchPolicy``) to ``evaluate``, which
    plays the builder's episodes (the same validation episode seeds every time,
    ``train.validation_seed``), and leaves the result for ``take``. One evaluation at a time: one due
    while another still runs waits for the next check. ``close`` gives a running one a little time,
    then cancels it (at the policy's next step).
    """

    def __init__(self, evaluate: EvaluatePolicy, every: int, obs_shape: tuple[int, ...],
                 n_actions: int, hidden: tuple[int, ...], dueling: bool, cnn: str = "nature"):
        self.evaluate, self.every = evaluate, every
        self._net_args = (tuple(obs_shape), n_actions, tuple(hidden), dueling, cnn)
        self.next_at = every
        self.failed: str | None = None
        self._thread: threading.Thread | None = None
        self._result: dict | None = None
        self._cancel = threading.Event()
        self._lock = threading.Lock()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def due(self, env_steps: int) -> bool:
        return self.every > 0 and self.failed is None and env_steps >= self.next_at and not self.running

    def start(self, online: torch.nn.Module, env_steps: int, **info: Any) -> None:
        """Evaluate ``online``'s current weights; the result carries ``env_steps`` and ``info``."""
        state = {k: v.detach().to("cpu", copy=True) for k, v in online.state_dict().items()}
        self.next_at = (env_steps // self.every + 1) * self.every
        self._thread = threading.Thread(target=self._run, args=(state, {"env_steps": env_steps, **info}),
                                        name="greedy-eval", daemon=True)
        self._thread.start()

    def take(self) -> dict | None:
        """The newest finished evaluation's result, once (None if none finished since the last take)."""
        with self._lock:
            result, self._result = self._result, None
        return result

    def close(self, timeout: float = 5.0) -> None:
        """Wait up to ``timeout`` s for a running evaluation to finish, then cancel it (at its
        policy's next step) and wait for the thread."""
        if self._thread is not None:
            self._thread.join(timeout)
        self._cancel.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def _run(self, state: dict[str, torch.Tensor], info: dict) -> None:
        began = time.monotonic()
        try:
            net = build_q_network(*self._net_args)
            net.load_state_dict(state)
            net.requires_grad_(False)
            cancel = self._cancel

            def batch(obs: np.ndarray) -> np.ndarray:
                if cancel.is_set():
                    raise _Cancelled
                x = np.asarray(obs)
                x = x if x.dtype == np.uint8 else x.astype(np.float32, copy=False)
                with torch.no_grad():
                    return net(torch.as_tensor(x)).argmax(dim=1).numpy()

            result = dict(self.evaluate(batch))
        except _Cancelled:
            return
        except Exception as exc:  # e.g. the simulator cannot be built on this node: off, said once
            self.failed = f"{type(exc).__name__}: {exc}"
            print(f"learner: greedy evaluation during training failed ({self.failed}); "
                  f"train.eval_every is off for the rest of this run", flush=True)
            return
        result.pop("crashes", None)
        result = {**info, **result, "eval_s": round(time.monotonic() - began, 2)}
        with self._lock:
            self._result = result
