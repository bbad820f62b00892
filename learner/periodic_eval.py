"""The greedy evaluation during training (``train.eval_every``, ``train.periodic_eval_episodes``):
a copy of the network the run hands out (``DoubleDQN.policy_net``) played greedily on a background
thread, by the ``EvaluatePolicy`` the builder hands the learner (``laneshift.actors.evaluation``:
the learner never imports the simulator itself), and its result written to the run's metrics
(``eval/*``).

Room: learner. May import: torch, numpy, the contract (``laneshift.qnet``) and ``learner.metrics``.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

import numpy as np
import torch

from laneshift.qnet import build_q_network

from .metrics import MetricsLog


#: A network's greedy policy over rows of observations (rows -> one action each).
BatchPolicy = Callable[[np.ndarray], np.ndarray]
#: The seam to the env-running side: play ``policy`` greedily for a fixed set of episodes (the
#: builder binds the env, the episode count and the seeds, and drives the ego vehicle and any
#: policy vehicles with it) and return the rates (``survival_rate``, ``achievement_rate``,
#: ``return_mean``, ...).
EvaluatePolicy = Callable[[BatchPolicy], dict]


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
                 n_actions: int, hidden: tuple[int, ...], dueling: bool, cnn: str = "nature", heads: int = 1):
        self.evaluate, self.every = evaluate, every
        # The evaluation acts in float32 whatever the learner's conv precision (acting always does).
        self._net_kwargs = {"obs_shape": tuple(obs_shape), "n_actions": n_actions, "hidden": tuple(hidden),
                            "dueling": dueling, "cnn": cnn, "heads": heads}
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

    def skip_past(self, env_steps: int) -> None:
        """The next evaluation is due at the first multiple of ``every`` above ``env_steps``: after one
        starts, and where a resumed run stands (its first due check once ran one at the resume point,
        then another at the next multiple: two in 1,600 env steps)."""
        if self.every > 0:
            self.next_at = (env_steps // self.every + 1) * self.every

    def start(self, online: torch.nn.Module, env_steps: int, **info: Any) -> None:
        """Evaluate ``online``'s current weights; the result carries ``env_steps`` and ``info``."""
        state = {k: v.detach().to("cpu", copy=True) for k, v in online.state_dict().items()}
        self.skip_past(env_steps)
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
            net = build_q_network(**self._net_kwargs)
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


#: TensorBoard's tags of one evaluation (``eval/<key>``).
EVAL_TAGS = ("survival_rate", "achievement_rate", "return_mean", "return_std", "length_mean", "eval_s")


def log_eval(metrics: MetricsLog, result: dict) -> None:
    """One finished evaluation: a line of metrics.jsonl, TensorBoard's ``eval/*`` and a line on stdout."""
    metrics.write("eval", result["env_steps"], result, {f"eval/{k}": result.get(k) for k in EVAL_TAGS})
    text = f"survival {result['survival_rate']:.0%}"
    if "achievement_rate" in result:
        text += f", achievement {result['achievement_rate']:.0%}"
    print(f"learner: greedy eval at {result['env_steps']:,} env steps (version {result.get('version')}): "
          f"{text}, return {result['return_mean']:.2f} over {result['episodes']} episodes", flush=True)
