"""The learner's status, computed once per log interval (``learner.log_every_s``): one typed value,
``LearnerStatus``, and what is made of it.

- ``LearnerStatus.to_dict()`` is the stats message the learner publishes (``stats_message``, which
  the links encode with ``wire.encode_json``; the launcher's progress line and the run's summary
  read it, by these field names, in this order) and what ``deploy.actors.LearnerActor.status``
  returns;
- ``record(status, replay_stats)``: the numbers of one ``learner`` line of ``metrics.jsonl``;
- ``tensorboard_scalars(status, replay_stats)``: TensorBoard's tags for the interval
  (``learner/*``, ``train/*``, ``actors/*``, ``replay/*``);
- ``IntervalRates``: the rates over the interval since the previous status.

Room: learner (component). May import: the standard library and ``learner.dqn``; never another
component.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

from .dqn import METRIC_NAMES


@dataclass
class LearnerStatus:
    """The learner at the end of one log interval. ``None``: not known yet (before the first
    update, the first episode, the first answer of the replay server)."""

    updates: int
    updates_per_s: float
    version: int
    lr: float
    phase: int
    episodes: int
    bad_episode_records: int
    #: The replay server's count of the env steps stored (TensorBoard's step is the learner's own
    #: count, which also takes the workers' reports: ``Learner.env_steps``).
    env_steps: int
    env_steps_per_s: float
    #: Share of the interval the update thread waited for a sampled batch (async mode): near 0
    #: when the learner bounds the run, large when the actors (or the replay) do.
    sample_wait_share: float
    sample_wait_s: float
    #: Since the first batch (None before it): what deploy.summary.wait_shares divides.
    training_s: float | None
    training_wait_s: float
    return_mean: float | None
    length_mean: float | None
    crash_rate: float | None
    #: Lane changes only: the LKA plant has no target lane.
    achievement_rate: float | None
    epsilon: float | None
    #: The factor on the imitation losses now (learner.imitation_final's schedule; 1 = whole).
    imitation_scale: float
    # The interval's last update (dqn.METRIC_NAMES), read back once per log interval.
    loss: float | None
    q_mean: float | None
    grad_norm: float | None
    td_abs: float | None
    margin_loss: float | None
    bc_loss: float | None
    replay_size: int | None
    demo_share_samples: float | None
    #: A sharded replay: rows drawn but cut when a shard refused its part (learner/shards.py).
    sample_rows_discarded: int
    #: Rows sampled ahead (learner/prefetch.py) that no update used: the end of the run.
    sample_rows_unused: int
    #: Each worker's weights version behind the learner's (the first few workers the replay reports).
    version_lag: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0
    #: Why the run stopped by itself (``train.stop_return``), None until it did.
    stop_reason: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The stats message's fields, in the order above."""
        return dataclasses.asdict(self)

    def stats_message(self, final: bool = False) -> dict[str, Any]:
        """The stats message's body: ``to_dict()``, and ``"done": true`` on the run's final one."""
        return {**self.to_dict(), "done": True} if final else self.to_dict()


class IntervalRates:
    """Rates over the interval since the previous call of ``take``."""

    def __init__(self, updates: int = 0, env_steps: int = 0) -> None:
        """``updates``, ``env_steps``: the counts at the start (a resumed run's restored ones)."""
        self._updates, self._steps, self._wait_s, self._time = updates, env_steps, 0.0, time.monotonic()

    def take(self, now: float, updates: int, env_steps: int, wait_s: float) -> tuple[float, float, float]:
        """(updates/s, env steps/s, the share of the interval spent waiting for batches)."""
        dt = max(now - self._time, 1e-6)
        rates = ((updates - self._updates) / dt, (env_steps - self._steps) / dt, (wait_s - self._wait_s) / dt)
        self._updates, self._steps, self._wait_s, self._time = updates, env_steps, wait_s, now
        return rates


def record(status: LearnerStatus, replay_stats: dict[str, Any]) -> dict[str, Any]:
    """The numbers of one ``learner`` line of metrics.jsonl: the status's numbers, each worker's
    version lag, and the replay's demo share and rates."""
    flat = {k: v for k, v in status.to_dict().items() if isinstance(v, (int, float)) and v is not None}
    flat.update({f"version_lag_{a}": lag for a, lag in status.version_lag.items()})
    if replay_stats:
        flat["replay_demo_share_buffer"] = replay_stats.get("demo_share_buffer", 0.0)
        flat.update({f"replay_{k}": v for k, v in replay_stats.get("rates", {}).items()})
    return flat


def tensorboard_scalars(status: LearnerStatus, replay_stats: dict[str, Any]) -> dict[str, float | None]:
    """TensorBoard's tags for one log interval (None values are left out by MetricsLog)."""
    s = status
    tb: dict[str, float | None] = {f"learner/{k}": getattr(s, k) for k in METRIC_NAMES}
    tb.update({"learner/updates": s.updates, "learner/updates_per_s": s.updates_per_s, "learner/version": s.version,
               "learner/phase": s.phase, "learner/sample_wait_share": s.sample_wait_share, "learner/lr": s.lr,
               "learner/imitation_scale": s.imitation_scale})
    tb.update({"train/env_steps_per_s": s.env_steps_per_s, "train/episodes": s.episodes,
               "train/return_mean": s.return_mean, "train/length_mean": s.length_mean,
               "train/crash_rate": s.crash_rate, "train/achievement_rate": s.achievement_rate,
               "train/epsilon": s.epsilon})
    lags = s.version_lag
    tb.update({f"actors/version_lag_{a}": lag for a, lag in lags.items()})
    if lags:
        tb["actors/version_lag_max"] = max(lags.values())
    r = replay_stats
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
