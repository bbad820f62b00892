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

What the loops use, each a module of its own: ``state`` (the files a restart goes on from),
``cpus`` (phase 1 on every CPU), ``episodes`` (the workers' episode records), ``status`` (the
status of each log interval and its TensorBoard tags), ``periodic_eval`` (the greedy evaluation
during training), ``batches`` (the back-off after a refusal, a batch cut into updates),
``prefetch`` (the next sample in flight: phase 1 and the async mode); ``process`` runs it as a
process (``laneshift learner --config run.yaml``).

Room: learner (component). May import: the contract and laneshift.learner; never another component.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from pathlib import Path

import torch

from laneshift import wire
from laneshift.config import RunConfig, worker_names
from laneshift.envspec import RECORDED_ENV_OPTIONS, EnvSpec
from laneshift.qnet import weights_of

from .batches import MAX_REPLY_BYTES, batches_per_request, retry_delay, sample_or_wait, split_updates
from .cpus import ThreadChooser, bf16_warning, phase1_cpus
from .dqn import METRIC_NAMES, DoubleDQN
from .episodes import EpisodeStats
from .metrics import MetricsLog
from .periodic_eval import EvaluatePolicy, GreedyEval, log_eval
from .prefetch import Prefetcher
from .seams import LearnerLinks
from .state import StateFiles
from .status import IntervalRates, LearnerStatus, record, tensorboard_scalars

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
        if (slow := bf16_warning(cfg.learner, self.agent.device)) is not None:
            print(f"learner: {slow}", flush=True)
        self.workers = worker_names(cfg.actor.workers)
        self.metrics = MetricsLog(self.run_dir)
        self.metrics.config(cfg.to_dict())
        self.files = StateFiles(self.run_dir)
        self.version = 0
        self.phase = 1 if cfg.replay.pretrains else 0
        self.episodes = EpisodeStats(lane_change=not cfg.env.is_lka)
        # TensorBoard's step: the run's env steps, never decreasing (restored with the learner state).
        self.env_steps = 0
        t = cfg.train
        # ``evaluate`` plays the env on the validation episodes (train.validation_seed; bound by the builder).
        self.evaluator = GreedyEval(evaluate, t.eval_interval, spec.schema.obs_shape, spec.schema.n_actions,
                                    cfg.learner.hidden, cfg.learner.dueling, cfg.learner.network_cnn,
                                    cfg.learner.heads) if t.eval_interval and evaluate is not None else None
        self.last_eval: dict | None = None
        self.last_update: Mapping[str, float] = {}  # the last update's metrics (dqn.UpdateMetrics: read lazily)
        self.replay_stats: dict = {}
        self.prefetcher: Prefetcher | None = None  # async mode: the next sample request in flight
        # learner.prefetch batches per request, fewer where the reply would be too large (pixels).
        self.per_request = batches_per_request(cfg.learner.batch_size, cfg.learner.prefetch, spec.schema.obs_shape,
                                               spec.schema.obs_dtype)
        if self.per_request < cfg.learner.prefetch:
            print(f"learner: {self.per_request} batches of {cfg.learner.batch_size} per sample request, not "
                  f"learner.prefetch {cfg.learner.prefetch} (a reply stays under "
                  f"{MAX_REPLY_BYTES // 2**20} MB)", flush=True)
        self.unused_sample_rows = 0  # rows sampled ahead that no update used (phase 1's end, the run's end)
        self.stop_reason: dict | None = None
        self.started = time.monotonic()
        self.last_status: LearnerStatus | None = None  # what the launcher's progress line reads
        self.sample_wait_s = 0.0  # the update thread's time waiting on a batch
        # When the first batch came, and sample_wait_s then: the wait while the replay fills to
        # replay.min_size is by design, so the run's summary ("which side bounded the run") counts
        # from here. It was most of the 2-10 % the learner was once measured to wait in whole runs
        # (`laneshift bench run`'s ``waits``).
        self.first_batch_at: float | None = None
        self._wait_before_first_batch = 0.0
        self._last_state_save = time.monotonic()
        self.restored_from: dict | None = self._restore()
        if self.evaluator is not None:
            self.evaluator.skip_past(self.env_steps)
        # Rates count from where the run stands now: a resumed run's restored updates and env steps
        # were not made in its first status interval (they read 6,171 updates/s and 3,268 steps/s).
        self.rates = IntervalRates(updates=self.agent.updates, env_steps=self.env_steps)
        self.prometheus = None  # learner.metrics_port >= 0: /metrics from the status of each log interval
        if self.lcfg.metrics_port >= 0:
            from .prometheus import LearnerMetricsServer

            self.prometheus = LearnerMetricsServer(self.lcfg.metrics_host, self.lcfg.metrics_port)

    # ------------------------------------------------------------------ restart

    @property
    def state_path(self) -> Path:
        return self.files.state_path

    @property
    def version_path(self) -> Path:
        return self.files.version_path

    @property
    def checkpoint_failures(self) -> int:
        """Checkpoint, state and published-version writes that failed (counted, retried later)."""
        return self.files.failures

    @property
    def metrics_write_failures(self) -> int:
        """metrics.jsonl lines and TensorBoard events lost to failed writes (a full run dir)."""
        return self.metrics.write_failures

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
        published, published_updates = self.files.read_published()
        state = self.files.load_state(self.agent.device)
        if state is None:
            if published < 0:
                return None  # a new run
            self.version = published + 1
            info = {"updates": 0, "version": self.version, "phase": self.phase, "path": None,
                    "updates_lost": published_updates}
            print(f"learner: no training state to restore (the learner stopped before its first state save); "
                  f"starting over from the initial network at weights version {self.version}, "
                  f"{published_updates} updates lost", flush=True)
            return info
        self.agent.load_state_dict(state["agent"])
        self.version = max(int(state["version"]), published) + 1
        self.phase = int(state["phase"])
        self.episodes.count = int(state["episodes"])
        self.env_steps = int(state.get("env_steps", 0))  # absent in states written before it was kept
        info = {"updates": self.agent.updates, "version": self.version, "phase": self.phase,
                "path": str(self.state_path), "updates_lost": max(0, published_updates - self.agent.updates)}
        print(f"learner: restored {self.state_path} (update {self.agent.updates}, phase {self.phase}); "
              f"continuing at weights version {self.version}", flush=True)
        return info

    def save_state(self) -> bool:
        """Write the full training state atomically; a failed write is counted and retried later."""
        state = {"agent": self.agent.state_dict(), "version": torch.tensor(self.version),
                 "phase": torch.tensor(self.phase), "episodes": torch.tensor(self.episodes.count),
                 "env_steps": torch.tensor(self.env_steps)}
        if not self.files.save_state(state):
            return False
        self._last_state_save = time.monotonic()
        return True

    # ------------------------------------------------------------------ weights

    def publish(self) -> None:
        # Before the broadcast: a restarted learner must never reuse a version actors saw.
        self.files.write_published(self.version, self.agent.updates)
        self.links.publish_weights(weights_of(self.agent.policy_net, self.version, self.phase, self.agent.updates))

    def checkpoint(self, name: str = "latest") -> Path | None:
        meta = {"version": self.version, "updates": self.agent.updates, "phase": self.phase,
                "env_id": self.spec.env_id, "obs_shape": ",".join(map(str, self.spec.schema.obs_shape)),
                "obs_dtype": self.spec.schema.obs_dtype, "n_actions": self.spec.schema.n_actions,
                "hidden": ",".join(map(str, self.lcfg.hidden)), "dueling": int(self.lcfg.dueling),
                "cnn": self.lcfg.network_cnn,
                "heads": self.lcfg.heads,
                "env_steps": self.episodes.env_steps, "elapsed_s": round(time.monotonic() - self.started, 1)}
        # The observation layout's options and the shield where the run set them, so `laneshift eval`
        # builds the env this network was trained in without being told (checkpoint_env_settings).
        meta.update({key: int(value) if isinstance(value, bool) else value
                     for key, value in self.spec.env_kwargs if key in RECORDED_ENV_OPTIONS})
        return self.files.save_policy(self.agent.policy_net, name, meta)

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
        self.links.publish_stats(self._status(), final=True)
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
        for part in split_updates(batch):
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
            self.links.send_priorities(wire.PriorityUpdate(index=batch.index, is_demo=batch.is_demo,
                                                           priority=priority))

    def _rehearsal_phase1(self) -> None:
        print(f"learner: {self.cfg.replay.demo_mode} phase 1: {self.lcfg.phase1_updates} updates on demos only",
              flush=True)
        if not self.lcfg.phase1_td:
            print("learner: phase 1 trains the imitation losses alone (learner.phase1_td=false)", flush=True)
        self.agent.td_loss = self.lcfg.phase1_td
        try:
            self._phase1_updates()
        finally:
            self.agent.td_loss = True
        if self.stop.is_set():
            return
        self.checkpoint("phase1")
        if not self._set_replay_phase(2):
            return
        # Phase 2: a new training run whose initial value is the phase-1 network.
        self.agent.reset_optimizer()
        self.phase, self.version = 2, self.version + 1
        self._follow_schedules()  # phase 2's schedules (learner.frozen_steps) from its first update
        self.publish()
        print(f"learner: {self.cfg.replay.demo_mode} phase 2 from the phase-1 network (version {self.version})",
              flush=True)

    def _phase1_updates(self) -> None:
        """Phase 1's updates on the demo shard, until ``learner.phase1_updates`` or a stop."""
        next_log = time.monotonic()
        with phase1_cpus(self.lcfg.phase1_threads, self.agent.device) as widened:
            if widened:
                print(f"learner: {widened}", flush=True)
            # learner.phase1_threads=0: one thread per CPU or one, whichever is faster now (cpus.py).
            chooser = ThreadChooser((torch.get_num_threads(), 1)) if widened and not self.lcfg.phase1_threads \
                else None
            said = None
            # Whole requests with the next one in flight (prefetch.py), as in phase 2: the round trip
            # and the decode overlap the updates (1.13-1.18x the updates/s; docs/performance-log.md).
            # The imitation losses alone read no next observations: the replies leave them out.
            request = wire.SampleRequest(self.lcfg.batch_size, self.per_request, next_obs=self.lcfg.phase1_td)
            ahead = Prefetcher(self.links.sample, lambda: request, self.stop)
            try:
                while (self.agent.updates + self.per_request <= self.lcfg.phase1_updates
                       and not self._should_stop()):
                    batch = ahead.take(timeout=0.5)
                    if batch is not None:
                        self._updates(batch)
                        if chooser is not None:
                            said = self._follow_thread_chooser(chooser, said)
                    next_log = self._log_when_due(next_log)
            finally:
                self.unused_sample_rows += ahead.close()  # demo rows sampled ahead, counted at the run's end
            # The last updates (fewer than one request's) are asked for exactly.
            while self.agent.updates < self.lcfg.phase1_updates and not self._should_stop():
                n = self.lcfg.phase1_updates - self.agent.updates
                batch = sample_or_wait(self.links.sample,
                                       wire.SampleRequest(self.lcfg.batch_size, n, next_obs=self.lcfg.phase1_td),
                                       self.stop.wait)
                if batch is not None:
                    self._updates(batch)
                next_log = self._log_when_due(next_log)

    def _follow_thread_chooser(self, chooser: ThreadChooser, said: int | None) -> int | None:
        """Set the torch threads ``chooser`` asks for; one log line when a round of its timings picks
        another count than the last one said. Returns the count said last."""
        count = chooser.tick(self.agent.updates, time.monotonic())
        if count is not None:
            torch.set_num_threads(count)
        if chooser.chosen is not None and chooser.chosen != said:
            print(f"learner: phase 1 on {chooser.chosen} torch thread{'s' if chooser.chosen > 1 else ''} "
                  f"({chooser.summary()}; timed again every {chooser.every_s:g} s)", flush=True)
            return chooser.chosen
        return said

    def _set_replay_phase(self, phase: int) -> bool:
        while not self.links.set_phase(phase):
            if self.stop.wait(0.2):
                return False
        return True

    def _log_when_due(self, next_log: float) -> float:
        """Status, metrics and a state save once ``next_log`` has passed; returns the next one
        (``learner.log_every_s`` on)."""
        if time.monotonic() < next_log:
            return next_log
        self._log()
        self._follow_schedules()
        self._maybe_save_state()
        return time.monotonic() + self.lcfg.log_every_s

    def _follow_schedules(self) -> None:
        """``learner.lr_final`` and ``learner.imitation_final``: the step size and the imitation
        losses' weight fall linearly with the run's env steps; ``learner.frozen_steps``: the
        frozen layers stay frozen until the run's env steps reach it (read once per log interval, the
        first one at the loop's start and at phase 2's, so a restored learner takes up its place at
        once; pre-training, which has no env steps, keeps both weights whole and trains everything)."""
        if self.phase == 1:
            return
        lcfg = self.lcfg
        if lcfg.frozen_steps:
            self.agent.set_frozen(self.env_steps < lcfg.frozen_steps)
        if lcfg.lr_final:
            self.agent.set_lr(linear_schedule(lcfg.lr, lcfg.lr_final, self.env_steps, self.cfg.train.env_steps))
        if lcfg.imitation_final < 1.0:
            fade = lcfg.imitation_fade_steps or self.cfg.train.env_steps
            self.agent.imitation_scale = linear_schedule(1.0, lcfg.imitation_final, self.env_steps, fade)

    def _maybe_save_state(self) -> None:
        every = self.lcfg.checkpoint_every_s
        if every and time.monotonic() - self._last_state_save >= every:
            self.save_state()

    def _async_step(self) -> None:
        if self.prefetcher is None:  # the next request is asked for while a batch trains (prefetch.py)
            self.prefetcher = Prefetcher(self.links.sample,
                                         lambda: wire.SampleRequest(self.lcfg.batch_size, self.per_request), self.stop)
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
            self.stop.wait(retry_delay(result))
            return
        else:
            self._updates(result)
        # ... then send the new parameters to all workers at once.
        self.version += 1
        self.publish()

    # ------------------------------------------------------------------ episodes and the stop criterion

    def _drain_episodes(self) -> None:
        for update in self.links.take_episodes():
            ep = self.episodes.accept(update)
            if ep is None:
                continue
            steps_before = self.episodes.env_steps
            self.episodes.add(ep)
            if ep.return_ >= self.cfg.train.stop_return and self.stop_reason is None:
                self._stop_on_return(ep.return_, steps_before)
            step = self._note_env_steps()
            crashed = float(ep.crashed)
            values = {"return": ep.return_, "length": ep.length, "crashed": crashed,
                      "on_target_lane": float(ep.on_target_lane), "epsilon": ep.epsilon,
                      "version_lag": float(self.version - ep.weights_version)}
            self.metrics.write("episode", step, {**values, "episode": self.episodes.count, "actor": ep.actor,
                                                 "env_steps": step},
                               {f"episode/{k}": v for k, v in values.items()})

    def _stop_on_return(self, ret: float, env_steps: int) -> None:
        """MATLAB's stop criterion: an episode reached the target return (``train.stop_return``)."""
        self.stop_reason = {"criterion": "stop_return", "return": ret, "episode": self.episodes.count,
                            "elapsed_s": round(time.monotonic() - self.started, 1), "env_steps": env_steps}
        print(f"learner: episode {self.episodes.count} returned {ret:.3f} >= train.stop_return "
              f"{self.cfg.train.stop_return}: stopping the run", flush=True)
        self.links.stop_all()

    def _note_env_steps(self) -> int:
        """The run's env steps so far as this learner knows them (TensorBoard's step): never less
        than before, whichever of the replay server's count and the workers' reports is ahead."""
        stored = int(self.replay_stats.get("actors_total", {}).get("env_steps", 0))
        self.env_steps = max(self.env_steps, stored, self.episodes.env_steps)
        return self.env_steps

    # ------------------------------------------------------------------ status and metrics

    def _status(self) -> LearnerStatus:
        now = time.monotonic()
        r = self.replay_stats
        env_steps = int(r.get("actors_total", {}).get("env_steps", 0))
        ups, steps_per_s, wait_share = self.rates.take(now, self.agent.updates, env_steps, self.sample_wait_s)
        actors = r.get("actors", {})  # the first few actors; totals cover all
        e = self.episodes
        return LearnerStatus(
            updates=self.agent.updates, updates_per_s=round(ups, 1), version=self.version, lr=self.agent.lr,
            phase=self.phase, episodes=e.count, bad_episode_records=e.bad_records,
            env_steps=env_steps, env_steps_per_s=round(steps_per_s, 1),
            sample_wait_share=round(min(wait_share, 1.0), 3), sample_wait_s=round(self.sample_wait_s, 2),
            training_s=round(now - self.first_batch_at, 2) if self.first_batch_at is not None else None,
            training_wait_s=round(self.sample_wait_s - self._wait_before_first_batch, 2)
            if self.first_batch_at is not None else 0.0,
            return_mean=e.return_mean(), length_mean=e.length_mean(), crash_rate=e.crash_rate(),
            achievement_rate=e.achievement_rate(), epsilon=e.epsilon(), imitation_scale=self.agent.imitation_scale,
            **{k: self.last_update.get(k) for k in METRIC_NAMES},
            replay_size=r.get("tables", {}).get("online", {}).get("size"),
            demo_share_samples=r.get("demo_share_recent_samples"),
            sample_rows_discarded=r.get("sharded_sampling", {}).get("discarded_rows", 0),
            sample_rows_unused=self.unused_sample_rows,
            version_lag={a: self.version - int(s.get("last_version", 0)) for a, s in actors.items()},
            elapsed_s=round(now - self.started, 1), stop_reason=self.stop_reason)

    def _log(self) -> None:
        self._drain_episodes()
        stats = self.links.replay_stats()
        if stats is not None:
            self.replay_stats = stats
        status = self._status()
        self.last_status = status
        if self.prometheus is not None:
            self.prometheus.update(status, env_steps=self._note_env_steps())
        self.links.publish_stats(status)
        scalars = tensorboard_scalars(status, self.replay_stats)
        step = self._note_env_steps()
        if self.phase == 1:  # demo-only updates, no env steps yet: the update count is the step
            step, scalars = self.agent.updates, {f"pretrain/{tag}": v for tag, v in scalars.items()}
        self.metrics.write("learner", step, record(status, self.replay_stats), scalars)
        self._eval_tick()

    def _final_metrics(self) -> dict[str, float | None]:
        """The run's final numbers for the HParams dashboard."""
        s = self.last_status
        out: dict[str, float | None] = {f"final/{k}": getattr(s, k, None)
                                        for k in ("return_mean", "length_mean", "crash_rate", "achievement_rate")}
        out.update({"final/updates": self.agent.updates, "final/env_steps": self.env_steps,
                    "final/episodes": self.episodes.count})
        if self.last_eval:
            out.update({f"final/eval_{k}": self.last_eval.get(k)
                        for k in ("survival_rate", "achievement_rate", "return_mean")})
        return out

    # ------------------------------------------------------------------ evaluation during training

    def _eval_tick(self) -> None:
        """Log a finished greedy evaluation; start the next when train.eval_every env steps passed."""
        if self.evaluator is None:
            return
        self._log_eval(self.evaluator.take())
        if self.phase != 1 and self.evaluator.due(self.env_steps):
            self.evaluator.start(self.agent.policy_net, self.env_steps, updates=self.agent.updates, version=self.version)

    def _log_eval(self, result: dict | None) -> None:
        if result is not None:
            self.last_eval = result
            log_eval(self.metrics, result)


def linear_schedule(start: float, end: float, env_steps: int, span: int) -> float:
    """``start`` at 0 env steps, ``end`` at ``span`` env steps and after, linear in between (the
    step size of ``learner.lr_final``, the imitation losses' factor of ``learner.imitation_final``).

    >>> linear_schedule(1e-3, 1e-4, 50, 100)
    0.00055
    """
    frac = min(max(env_steps / span, 0.0), 1.0) if span > 0 else 1.0
    return start + frac * (end - start)
