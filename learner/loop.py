"""The learner process: pull batches, update Double DQN, broadcast weights.

Cadence per parallel mode (MATLAB's parallel training options):

- ``async``: learn from whatever the replay server has; every ``publish_every`` updates a new
  weights version is broadcast and actors pick it up between their send batches.
- ``sync``: wait until every worker delivered a batch made with the current version, do
  ``updates_per_round`` updates, then broadcast the next version to all at once; workers wait.

Rehearsal (the paper's 予行型): phase 1 runs ``phase1_updates`` updates on the demo shard alone
(actors wait), saves ``checkpoints/phase1.safetensors``, switches the replay server to phase 2 and
starts a new training run from that network (fresh optimizer, target = online). ``dqfd`` has the
same phase 1 (DQfD's pre-training); its phase 2 keeps the demo region in the buffer.

Metrics (``learner/metrics.py``): TensorBoard scalars at env steps (``learner/*``: every
``dqn.UpdateMetrics`` of the interval's last update, update rate, weights version; ``train/*``: the
workers' episodes; ``replay/*``; ``actors/*``: version lag; ``episode/*``: one point per episode;
``eval/*``: the greedy evaluation every ``train.eval_every`` env steps); phase 1, which has no env
steps, logs the same under ``pretrain/`` at update counts. The env-step count is the largest of the
replay server's count, the workers' episode reports and the count restored with the learner state,
so TensorBoard's step never goes back, on a restart or ``--resume`` either.

Run it with ``laneshift learner --config run.yaml``.

Room: learner (component). May import: the contract and laneshift.learner; never another component.
"""

from __future__ import annotations

import collections
import signal
import sys
import threading
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from laneshift import transport, wire
from laneshift.config import RunConfig, worker_budgets, worker_names  # noqa: F401 - re-exported
from laneshift.envspec import EnvSpec
from laneshift.qnet import save_checkpoint, to_wire

from .dqn import METRIC_NAMES, DoubleDQN
from .links import ZenohLearnerLinks
from .metrics import EvaluatePolicy, GreedyEval, MetricsLog
from .prefetch import Prefetcher
from .seams import LearnerLinks


#: How long the end of a run waits for a running greedy evaluation (train.eval_every) before cancelling it.
FINAL_EVAL_WAIT_S = 10.0


class Learner:
    """The learner's loop: batches from ``links``, Double DQN updates, weights back to ``links``.
    ``evaluate`` (from the builder) plays the greedy policy for ``train.eval_every``; None: off."""

    def __init__(self, cfg: RunConfig, spec: EnvSpec, links: LearnerLinks, stop: threading.Event,
                 evaluate: EvaluatePolicy | None = None):
        self.cfg, self.lcfg, self.spec = cfg, cfg.learner, spec
        self.links, self.stop = links, stop
        self.run_dir = Path(cfg.train.run_dir)
        self.agent = DoubleDQN(spec.schema.obs_shape, spec.schema.n_actions, cfg.learner)
        self.workers = worker_names(cfg.actor.workers)
        self.metrics = MetricsLog(self.run_dir)
        self.metrics.config(cfg.to_dict())
        self.version = 0
        self.phase = 1 if cfg.replay.pretrains else 0
        # Running statistics for logs.
        self.returns: collections.deque[float] = collections.deque(maxlen=100)
        self.lengths: collections.deque[float] = collections.deque(maxlen=100)
        self.crashes: collections.deque[float] = collections.deque(maxlen=100)
        self.achieved: collections.deque[float] = collections.deque(maxlen=100)
        self.episodes = 0
        self.bad_episode_records = 0  # episode records that failed wire.decode_episode
        self.actor_steps: dict[str, int] = {}
        self.actor_epsilon: dict[str, float] = {}  # each worker's epsilon at its newest episode
        # TensorBoard's step: the run's env steps, never decreasing (restored with the learner state).
        self.env_steps = 0
        t = cfg.train
        # ``evaluate`` plays the env on the validation episodes (train.validation_seed; bound by the builder).
        self.evaluator = GreedyEval(evaluate, t.eval_interval, spec.schema.obs_shape, spec.schema.n_actions,
                                    cfg.learner.hidden, cfg.learner.dueling,
                                    cfg.learner.cnn) if t.eval_interval and evaluate is not None else None
        self.last_eval: dict | None = None
        self.last_update: Mapping[str, float] = {}  # the last update's metrics (dqn.UpdateMetrics: read lazily)
        self.replay_stats: dict = {}
        self.prefetcher: Prefetcher | None = None  # async mode: the next sample request in flight
        self.unused_sample_rows = 0  # rows sampled ahead that no update used (the end of a run)
        self.stop_reason: dict | None = None
        self.started = time.monotonic()
        self._updates_at_last_log, self._steps_at_last_log, self._time_at_last_log = 0, 0, time.monotonic()
        self.last_status: dict = {}
        self.sample_wait_s = self._wait_at_last_log = 0.0  # the update thread's time waiting on a batch
        # When the first batch came, and sample_wait_s then: the wait while the replay fills to
        # replay.min_size is by design, so the run's summary ("which side bounded the run") counts
        # from here. It was most of the 2-10 % the learner was once measured to wait in whole runs
        # (`laneshift bench run`'s ``waits``).
        self.first_batch_at: float | None = None
        self._wait_before_first_batch = 0.0
        self.checkpoint_failures = 0  # writes that failed (full disk, read-only dir): counted, retried later
        self._last_state_save = time.monotonic()
        self.restored_from: dict | None = self._restore()
        self.prometheus = None  # learner.metrics_port >= 0: /metrics from the status of each log interval
        if self.lcfg.metrics_port >= 0:
            from .prometheus import LearnerMetricsServer

            self.prometheus = LearnerMetricsServer(self.lcfg.metrics_host, self.lcfg.metrics_port)

    # ------------------------------------------------------------------ restart

    @property
    def state_path(self) -> Path:
        return self.run_dir / "checkpoints" / "learner_state.pt"

    @property
    def version_path(self) -> Path:
        return self.run_dir / "checkpoints" / "published_version"

    def _restore(self) -> dict | None:
        """A restarted (or resumed) learner goes on from its last full state.

        The weights version continues above every version this run ever published (the
        ``published_version`` file, written before each broadcast, holds it and the update count it
        was published at), so actors, which ignore versions they already passed, take the new
        weights at once and versions never go backwards: also when the learner died before its
        first state save, when it starts from its initial network. ``updates_lost``: the updates
        published and not in the restored state (all of them without one), reported in the
        status and the run's summary.
        """
        published, published_updates = _read_published(self.version_path)
        if not self.state_path.exists():
            if published < 0:
                return None  # a new run
            self.version = published + 1
            info = {"updates": 0, "version": self.version, "phase": self.phase, "path": None,
                    "updates_lost": published_updates}
            print(f"learner: no training state to restore (the learner stopped before its first state save); "
                  f"starting over from the initial network at weights version {self.version}, "
                  f"{published_updates} updates lost", flush=True)
            return info
        state = torch.load(self.state_path, map_location=self.agent.device, weights_only=True)
        self.agent.load_state_dict(state["agent"])
        self.version = max(int(state["version"]), published) + 1
        self.phase = int(state["phase"])
        self.episodes = int(state["episodes"])
        self.env_steps = int(state.get("env_steps", 0))  # absent in states written before it was kept
        info = {"updates": self.agent.updates, "version": self.version, "phase": self.phase,
                "path": str(self.state_path), "updates_lost": max(0, published_updates - self.agent.updates)}
        print(f"learner: restored {self.state_path} (update {self.agent.updates}, phase {self.phase}); "
              f"continuing at weights version {self.version}", flush=True)
        return info

    def save_state(self) -> bool:
        """Write the full training state atomically; a failed write is counted and retried later."""
        state = {"agent": self.agent.state_dict(), "version": torch.tensor(self.version),
                 "phase": torch.tensor(self.phase), "episodes": torch.tensor(self.episodes),
                 "env_steps": torch.tensor(self.env_steps)}
        tmp = self.state_path.with_suffix(".tmp")
        try:
            self.state_path.parent.mkdir(parents=True, exist_ok=True)
            torch.save(state, tmp)
            tmp.replace(self.state_path)  # the previous complete state stays valid until this rename
        except (OSError, RuntimeError) as exc:  # torch wraps ENOSPC in RuntimeError
            self._checkpoint_failed("learner state", exc)
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
            return False
        self._last_state_save = time.monotonic()
        return True

    def _checkpoint_failed(self, what: str, exc: Exception) -> None:
        self.checkpoint_failures += 1
        print(f"learner: writing the {what} failed ({exc}); training goes on, retrying at the next checkpoint "
              f"({self.checkpoint_failures} failed so far)", flush=True)

    # ------------------------------------------------------------------ weights

    def publish(self) -> None:
        try:  # before the broadcast: a restarted learner must never reuse a version actors saw
            _write_published(self.version_path, self.version, self.agent.updates)
        except OSError as exc:
            self._checkpoint_failed("published version", exc)
        self.links.publish_weights(to_wire(self.agent.policy_net, self.version, self.phase, self.agent.updates))

    def checkpoint(self, name: str = "latest") -> Path | None:
        meta = {"version": self.version, "updates": self.agent.updates, "phase": self.phase,
                "env_id": self.spec.env_id, "obs_shape": ",".join(map(str, self.spec.schema.obs_shape)),
                "obs_dtype": self.spec.schema.obs_dtype, "n_actions": self.spec.schema.n_actions,
                "hidden": ",".join(map(str, self.lcfg.hidden)), "dueling": int(self.lcfg.dueling), "cnn": self.lcfg.cnn,
                "env_steps": sum(self.actor_steps.values()), "elapsed_s": round(time.monotonic() - self.started, 1)}
        try:
            return save_checkpoint(self.agent.policy_net, self.run_dir / "checkpoints" / f"{name}.safetensors", meta)
        except OSError as exc:  # a full disk or read-only run dir must not end training
            self._checkpoint_failed(f"{name} checkpoint", exc)
            return None

    # ------------------------------------------------------------------ main loop

    def run(self) -> None:
        self.publish()
        print(f"learner: version {self.version} published on {self.agent.device}; mode {self.cfg.replay.demo_mode}, "
              f"parallel {self.cfg.train.parallel}, "
              f"{sum(p.numel() for p in self.agent.online.parameters())} parameters", flush=True)
        if self.phase == 1:
            self._rehearsal_phase1()
        elif self.phase == 2 and self.restored_from:
            self._set_replay_phase(2)  # a replay server restarted without a checkpoint starts in phase 1
        next_log = time.monotonic()
        while not self._should_stop():
            if self.cfg.train.parallel == "sync":
                self._sync_round()
            else:
                self._async_step()
            next_log = self._log_when_due(next_log)
        self._finish()

    def _finish(self) -> None:
        """The end of a run: last metrics, checkpoints and state, HParams, files closed."""
        if self.prefetcher is not None:
            self.unused_sample_rows += self.prefetcher.close()
        self._log()  # starts the last evaluation if train.eval_every env steps passed since the previous one
        if self.evaluator is not None:  # the evaluation running now is waited for, briefly, then cancelled
            self.evaluator.close(timeout=FINAL_EVAL_WAIT_S)
            self._log_eval(self.evaluator.take())
        self.checkpoint("latest")
        self.checkpoint("final")
        self.save_state()
        self.links.publish_stats(wire.encode_json({**self._status(), "done": True}))
        self.metrics.hparams(self.cfg.to_dict(), self._final_metrics(), self.env_steps)
        self.metrics.close()
        if self.prometheus is not None:
            self.prometheus.close()
        print(f"learner: stopped after {self.agent.updates} updates, version {self.version}", flush=True)

    def _should_stop(self) -> bool:
        if self.links.stop_requested():
            self.stop.set()
        return self.stop.is_set()

    def _updates(self, batch: wire.SampledBatch) -> None:
        prioritized = bool(batch.info.get("prioritized"))
        td_abs = []
        for part in _split(batch):
            # The metrics stay tensors until _status reads them (once per log interval): no
            # read-back per update. The |TD errors| are read back once per batch, and only for
            # a prioritized replay.
            self.last_update = self.agent.update(part)
            if prioritized:
                td_abs.append(self.agent.last_td_abs_tensor)
            if self.agent.updates % self.lcfg.checkpoint_every == 0:
                self.checkpoint("latest")
                if self.lcfg.keep_checkpoints:
                    self.checkpoint(f"u{self.agent.updates:08d}")
        if prioritized:
            priority = torch.cat(td_abs).to("cpu", torch.float32).numpy()
            self.links.send_priorities(wire.encode_priorities(wire.PriorityUpdate(
                index=batch.index, is_demo=batch.is_demo, priority=priority)))

    def _fetch(self, req: wire.SampleRequest) -> wire.SampledBatch | None:
        """One sample request; on 'not ready' or no answer waits a little and returns None."""
        result = self.links.sample(req)
        if isinstance(result, wire.SampledBatch):
            return result
        self._back_off(result)
        return None

    def _back_off(self, result: wire.WireError | None) -> None:
        """Wait as long as the replay server asked (``retry_after_ms``), or 0.1 s if it did not answer."""
        delay = getattr(result, "retry_after_ms", 0) / 1000 if result is not None else 0.1
        self.stop.wait(max(delay, 0.001))

    def _rehearsal_phase1(self) -> None:
        print(f"learner: {self.cfg.replay.demo_mode} phase 1: {self.lcfg.phase1_updates} updates on demos only",
              flush=True)
        next_log = time.monotonic()
        while self.agent.updates < self.lcfg.phase1_updates and not self._should_stop():
            n = min(self.lcfg.prefetch, self.lcfg.phase1_updates - self.agent.updates)
            batch = self._fetch(wire.SampleRequest(self.lcfg.batch_size, n))
            if batch is not None:
                self._updates(batch)
            next_log = self._log_when_due(next_log)
        if self.stop.is_set():
            return
        self.checkpoint("phase1")
        if not self._set_replay_phase(2):
            return
        # Phase 2: a new training run whose initial value is the phase-1 network.
        self.agent.reset_optimizer()
        self.phase, self.version = 2, self.version + 1
        self.publish()
        print(f"learner: {self.cfg.replay.demo_mode} phase 2 from the phase-1 network (version {self.version})",
              flush=True)

    def _set_replay_phase(self, phase: int) -> bool:
        while (reply := self.links.replay_control({"cmd": "set_phase", "phase": phase})) is None or not reply.get("ok"):
            if self.stop.wait(0.2):
                return False
        return True

    def _log_when_due(self, next_log: float) -> float:
        """Status, metrics and a state save once ``next_log`` has passed; returns the next one
        (``learner.log_every_s`` on)."""
        if time.monotonic() < next_log:
            return next_log
        self._log()
        self._follow_lr_schedule()
        self._maybe_save_state()
        return time.monotonic() + self.lcfg.log_every_s

    def _follow_lr_schedule(self) -> None:
        """``learner.lr_final``: the step size falls linearly from ``lr`` with the run's env steps
        (read once per log interval; pre-training, which has none, keeps ``lr``)."""
        if not self.lcfg.lr_final or self.phase == 1:
            return
        self.agent.set_lr(scheduled_lr(self.lcfg.lr, self.lcfg.lr_final, self.env_steps, self.cfg.train.env_steps))

    def _maybe_save_state(self) -> None:
        every = self.lcfg.checkpoint_every_s
        if every and time.monotonic() - self._last_state_save >= every:
            self.save_state()

    def _async_step(self) -> None:
        if self.prefetcher is None:  # the next request is asked for while a batch trains (prefetch.py)
            self.prefetcher = Prefetcher(self.links.sample,
                                         lambda: wire.SampleRequest(self.lcfg.batch_size, self.lcfg.prefetch), self.stop)
        waited = time.monotonic()
        batch = self.prefetcher.take(timeout=0.5)  # refusals are waited out on the prefetch thread
        now = time.monotonic()
        self.sample_wait_s += now - waited  # the update thread idle: the actors bound the run
        if batch is None:
            return
        if self.first_batch_at is None:
            self.first_batch_at, self._wait_before_first_batch = now, self.sample_wait_s
        before = self.agent.updates
        self._updates(batch)
        if self.agent.updates // self.lcfg.publish_every > before // self.lcfg.publish_every:
            self.version += 1
            self.publish()

    def _sync_round(self) -> None:
        # Wait until every worker delivered a batch made with the current version ...
        req = wire.SampleRequest(self.lcfg.batch_size, self.lcfg.updates_per_round, min_version=self.version,
                                 actors=tuple(self.workers))
        result = self.links.sample(req)
        if isinstance(result, wire.WireError) and result.reason == "rate_limited":
            pass  # ... before the replay holds enough to learn, the round just advances the version
        elif not isinstance(result, wire.SampledBatch):
            self._back_off(result)
            return
        else:
            self._updates(result)
        # ... then send the new parameters to all workers at once.
        self.version += 1
        self.publish()

    # ------------------------------------------------------------------ logging

    def _drain_episodes(self) -> None:
        for payload in self.links.take_episodes():
            try:
                ep = wire.decode_episode(payload)
            except wire.WireError as exc:  # counted and said once: never a silent loss
                self.bad_episode_records += 1
                if self.bad_episode_records == 1:
                    print(f"learner: skipped an unreadable episode record ({exc}); "
                          f"the count is bad_episode_records in the status", flush=True)
                continue
            ret, length = ep.return_, ep.length
            self.episodes += 1
            if ret >= self.cfg.train.stop_return and self.stop_reason is None:
                # MATLAB's stop criterion: an episode reached the target return.
                self.stop_reason = {"criterion": "stop_return", "return": ret, "episode": self.episodes,
                                    "elapsed_s": round(time.monotonic() - self.started, 1),
                                    "env_steps": sum(self.actor_steps.values())}
                print(f"learner: episode {self.episodes} returned {ret:.3f} >= train.stop_return "
                      f"{self.cfg.train.stop_return}: stopping the run", flush=True)
                self.links.stop_all()
            actor = ep.actor
            crashed = float(ep.crashed)
            on_target = float(ep.on_target_lane)
            self.returns.append(ret)
            self.lengths.append(length)
            self.crashes.append(crashed)
            self.achieved.append(on_target * (1.0 - crashed))
            # A worker's count only grows (a restarted worker resumes from what the replay server stored).
            self.actor_steps[actor] = max(self.actor_steps.get(actor, 0), ep.env_steps)
            self.actor_epsilon[actor] = ep.epsilon
            step = self._note_env_steps()
            values = {"return": ret, "length": length, "crashed": crashed, "on_target_lane": on_target,
                      "epsilon": self.actor_epsilon[actor],
                      "version_lag": float(self.version - ep.weights_version)}
            self.metrics.write("episode", step, {**values, "episode": self.episodes, "actor": actor,
                                                 "env_steps": step},
                               {f"episode/{k}": v for k, v in values.items()})

    def _note_env_steps(self) -> int:
        """The run's env steps so far as this learner knows them (TensorBoard's step): never less
        than before, whichever of the replay server's count and the workers' reports is ahead."""
        stored = int(self.replay_stats.get("actors_total", {}).get("env_steps", 0))
        self.env_steps = max(self.env_steps, stored, sum(self.actor_steps.values()))
        return self.env_steps

    def _status(self) -> dict:
        now = time.monotonic()
        dt = max(now - self._time_at_last_log, 1e-6)
        ups = (self.agent.updates - self._updates_at_last_log) / dt
        actors = self.replay_stats.get("actors", {})  # the first few actors; totals below cover all
        env_steps = int(self.replay_stats.get("actors_total", {}).get("env_steps", 0))
        steps_per_s = (env_steps - self._steps_at_last_log) / dt
        wait_share = (self.sample_wait_s - self._wait_at_last_log) / dt
        self._updates_at_last_log, self._steps_at_last_log, self._time_at_last_log = self.agent.updates, env_steps, now
        self._wait_at_last_log = self.sample_wait_s
        return {
            "updates": self.agent.updates, "updates_per_s": round(ups, 1), "version": self.version, "lr": self.agent.lr,
            "phase": self.phase, "episodes": self.episodes, "bad_episode_records": self.bad_episode_records,
            "env_steps": env_steps, "env_steps_per_s": round(steps_per_s, 1),
            # Share of the interval the update thread waited for a sampled batch (async mode): near 0
            # when the learner bounds the run, large when the actors (or the replay) do.
            "sample_wait_share": round(min(wait_share, 1.0), 3), "sample_wait_s": round(self.sample_wait_s, 2),
            # Since the first batch (None before it): what deploy.summary.wait_shares divides.
            "training_s": round(now - self.first_batch_at, 2) if self.first_batch_at is not None else None,
            "training_wait_s": round(self.sample_wait_s - self._wait_before_first_batch, 2)
            if self.first_batch_at is not None else 0.0,
            "return_mean": float(np.mean(self.returns)) if self.returns else None,
            "length_mean": float(np.mean(self.lengths)) if self.lengths else None,
            "crash_rate": float(np.mean(self.crashes)) if self.crashes else None,
            # Lane changes only: the LKA plant has no target lane.
            "achievement_rate": float(np.mean(self.achieved)) if self.achieved and not self.cfg.env.is_lka else None,
            "epsilon": float(np.mean(list(self.actor_epsilon.values()))) if self.actor_epsilon else None,
            # The interval's last update (dqn.METRIC_NAMES: loss, q_mean, grad_norm, td_abs, margin_loss,
            # bc_loss), read back here, once per log interval; None before the first update.
            **{k: self.last_update.get(k) for k in METRIC_NAMES},
            "replay_size": self.replay_stats.get("tables", {}).get("online", {}).get("size"),
            "demo_share_samples": self.replay_stats.get("demo_share_recent_samples"),
            # A sharded replay: rows drawn but cut when a shard refused its part (learner/shards.py).
            "sample_rows_discarded": self.replay_stats.get("sharded_sampling", {}).get("discarded_rows", 0),
            # Rows sampled ahead (learner/prefetch.py) that no update used: the end of the run.
            "sample_rows_unused": self.unused_sample_rows,
            "version_lag": {a: self.version - int(s.get("last_version", 0)) for a, s in actors.items()},
            "elapsed_s": round(now - self.started, 1), "stop_reason": self.stop_reason,
        }

    def _log(self) -> None:
        self._drain_episodes()
        stats = self.links.replay_stats()
        if stats is not None:
            self.replay_stats = stats
        status = self._status()
        self.last_status = status  # what the launcher's progress line reads (deploy.actors.LearnerActor.status)
        if self.prometheus is not None:
            self.prometheus.update({**status, "env_steps": self._note_env_steps()})
        self.links.publish_stats(wire.encode_json(status))
        flat = {k: v for k, v in status.items() if isinstance(v, (int, float)) and v is not None}
        flat.update({f"version_lag_{a}": lag for a, lag in status["version_lag"].items()})
        if self.replay_stats:
            flat["replay_demo_share_buffer"] = self.replay_stats.get("demo_share_buffer", 0.0)
            flat.update({f"replay_{k}": v for k, v in self.replay_stats.get("rates", {}).items()})
        scalars = self._tb_scalars(status)
        step = self._note_env_steps()
        if self.phase == 1:  # demo-only updates, no env steps yet: the update count is the step
            step, scalars = self.agent.updates, {f"pretrain/{tag}": v for tag, v in scalars.items()}
        self.metrics.write("learner", step, flat, scalars)
        self._eval_tick()

    def _tb_scalars(self, status: dict) -> dict[str, float | None]:
        """TensorBoard's tags for one log interval (None values are left out by MetricsLog)."""
        tb: dict[str, float | None] = {f"learner/{k}": status.get(k) for k in METRIC_NAMES}
        tb.update({f"learner/{k}": status[k] for k in ("updates", "updates_per_s", "version", "phase", "sample_wait_share", "lr")})
        tb.update({f"train/{k}": status[k] for k in ("env_steps_per_s", "episodes", "return_mean", "length_mean",
                                                      "crash_rate", "achievement_rate", "epsilon")})
        lags = status["version_lag"]
        tb.update({f"actors/version_lag_{a}": lag for a, lag in lags.items()})
        if lags:
            tb["actors/version_lag_max"] = max(lags.values())
        r = self.replay_stats
        if r:
            online = r.get("tables", {}).get("online", {})
            total = r.get("actors_total", {})
            size, capacity = online.get("size"), online.get("capacity")
            tb.update({"replay/size": size, "replay/fill": size / capacity if size is not None and capacity else None,
                       "replay/demo_share_buffer": r.get("demo_share_buffer"),
                       "replay/demo_share_samples": r.get("demo_share_recent_samples"),
                       "replay/sampled_rows": r.get("sampled_rows"), "replay/env_steps": total.get("env_steps"),
                       "replay/lost_items": total.get("lost_items")})
            tb.update({f"replay/{k}": v for k, v in r.get("rates", {}).items()})
        return tb

    # ------------------------------------------------------------------ evaluation during training

    def _eval_tick(self) -> None:
        """Log a finished greedy evaluation; start the next when train.eval_every env steps passed."""
        if self.evaluator is None:
            return
        self._log_eval(self.evaluator.take())
        if self.phase != 1 and self.evaluator.due(self.env_steps):
            self.evaluator.start(self.agent.policy_net, self.env_steps, updates=self.agent.updates, version=self.version)

    def _log_eval(self, result: dict | None) -> None:
        if result is None:
            return
        self.last_eval = result
        self.metrics.write("eval", result["env_steps"], result,
                           {f"eval/{k}": result.get(k) for k in ("survival_rate", "achievement_rate", "return_mean",
                                                                 "return_std", "length_mean", "eval_s")})
        text = f"survival {result['survival_rate']:.0%}"
        if "achievement_rate" in result:
            text += f", achievement {result['achievement_rate']:.0%}"
        print(f"learner: greedy eval at {result['env_steps']:,} env steps (version {result.get('version')}): "
              f"{text}, return {result['return_mean']:.2f} over {result['episodes']} episodes", flush=True)

    def _final_metrics(self) -> dict[str, float | None]:
        """The run's final numbers for the HParams dashboard."""
        s = self.last_status
        out = {f"final/{k}": s.get(k) for k in ("return_mean", "length_mean", "crash_rate", "achievement_rate")}
        out.update({"final/updates": self.agent.updates, "final/env_steps": self.env_steps,
                    "final/episodes": self.episodes})
        if self.last_eval:
            out.update({f"final/eval_{k}": self.last_eval.get(k)
                        for k in ("survival_rate", "achievement_rate", "return_mean")})
        return out


def scheduled_lr(lr: float, lr_final: float, env_steps: int, budget: int) -> float:
    """``lr`` at 0 env steps, ``lr_final`` at the budget and after it, linear in between.

    >>> scheduled_lr(1e-3, 1e-4, 50, 100)
    0.00055
    """
    frac = min(max(env_steps / budget, 0.0), 1.0) if budget > 0 else 1.0
    return lr + frac * (lr_final - lr)


def _read_published(path: Path) -> tuple[int, int]:
    """(the highest weights version published, the update count it was published at); (-1, 0) if
    none was. A file of one number (written before the update count was kept) gives 0 updates."""
    try:
        fields = [int(x) for x in path.read_text().split()]
    except (OSError, ValueError):
        return -1, 0
    if not fields:
        return -1, 0
    return fields[0], fields[1] if len(fields) > 1 else 0


def _write_published(path: Path, version: int, updates: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(f"{version} {updates}")
    tmp.replace(path)


#: The per-row fields of a sampled batch that DoubleDQN.update reads.
UPDATE_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "steps", "weight", "is_demo")


def _split(batch: wire.SampledBatch) -> list[dict[str, np.ndarray]]:
    """The batch's ``num_batches`` update batches: row slices (views, no copies) of each field."""
    fields = {k: getattr(batch, k) for k in UPDATE_FIELDS}
    rows, rest = divmod(len(batch.action), batch.num_batches)
    if rest:
        raise ValueError(f"{len(batch.action)} rows do not split into {batch.num_batches} batches")
    return [{k: v[i * rows:(i + 1) * rows] for k, v in fields.items()} for i in range(batch.num_batches)]


#: The learner process's GIL switch interval (Python's default: 5 ms). The update thread gives the
#: GIL up around each torch op; when the prefetch thread's decode or a zenoh callback holds it, the
#: update waits for up to this long. 0.5 ms: +2.5 % and +4 % env steps/s in two alternating rounds
#: of a 40,000-step run, alternating with the default (`laneshift train --local --workers 2 --scenario
#: straight --env-steps 40000`, rates from its metrics.jsonl; docs/performance.md). A learner process's
#: setting only:
#: in-process mode runs every component in one process and keeps Python's default.
LEARNER_SWITCH_INTERVAL_S = 0.0005


#: glibc malloc in the learner process: blocks up to this size come from the heap, not from a
#: fresh mmap, and freed heap goes back to the system only above TRIM_THRESHOLD_BYTES. With glibc's
#: defaults every update's 256 KB activations and each decoded 175 KB batch were mapped and
#: unmapped anew: 5,000-8,000 page faults a second at ~185 updates/s, 4 % of a core in the kernel
#: (a 40,000-step run, /proc/<pid>/stat); with these, about 5 a second. The learner's working set
#: is a few MB, so the memory kept back is too.
MMAP_THRESHOLD_BYTES = 8 * 2**20
TRIM_THRESHOLD_BYTES = 64 * 2**20


def tune_learner_process() -> None:
    """The learner process's own settings: the GIL switch interval and its allocator."""
    sys.setswitchinterval(LEARNER_SWITCH_INTERVAL_S)
    _tune_malloc()


def _tune_malloc() -> None:
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): keep the allocator's defaults
        return
    m_trim_threshold, m_mmap_threshold = -1, -3  # glibc's <malloc.h>
    mallopt(m_mmap_threshold, MMAP_THRESHOLD_BYTES)
    mallopt(m_trim_threshold, TRIM_THRESHOLD_BYTES)


def run_learner(cfg: RunConfig, spec: EnvSpec, evaluate: EvaluatePolicy | None = None) -> int:
    """Learner process entry point: runs until a stop command, SIGINT or SIGTERM. ``spec``: the
    env's, computed by whoever starts the process; ``evaluate``: for ``train.eval_every``."""
    # learner.torch_threads (default 1), a deliberate choice: the learner shares its node with the
    # replay server, the zenoh router and often actors, and a second intra-op thread would compete
    # with them for the same cores (on a 2-core node, for all of them) while the default MLP's
    # matmuls (batch 256 x 256 units) are small for intra-op parallelism; a GPU learner's CPU side
    # only launches kernels. Measured on a 2-core machine with the whole system running, two threads
    # made the run slower (0.71x and 0.95x env steps/s against one thread; `laneshift bench run
    # --train-args "--workers 2 --set learner.torch_threads=2"` measures a run's env steps/s); raise
    # it on a node whose cores the learner has to itself.
    torch.set_num_threads(cfg.learner.torch_threads)
    tune_learner_process()
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        # Waits for the router as long as it takes (it may start later; transport.connect_timeout_s
        # bounds it where the config has one), saying so in a line every 30 s.
        session = transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes, who="learner",
                                         stop=stop, batching=False)  # sample requests: see session_config
    except InterruptedError as exc:  # SIGINT/SIGTERM before any router answered
        print(f"learner: {exc}", flush=True)
        return 0
    except ConnectionError as exc:  # the connect timeout passed: one line naming the endpoint
        print(f"learner: {exc}", file=sys.stderr, flush=True)
        return 1
    with session:
        links = ZenohLearnerLinks(session, cfg, spec.schema, stop)
        Learner(cfg, spec, links, stop, evaluate).run()
    return 0
