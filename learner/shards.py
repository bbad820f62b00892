"""Sampling a sharded replay: N replay servers seen by the learner as one ``ReplayClient``.

With ``replay.shards`` = N each env worker sends to one shard (``wire.shard_of``, a stable
function of its name) and each shard holds ``capacity / N`` items. ``ShardedReplay`` wraps one
``ReplayShardClient`` per shard (zenoh or in-process alike), sends every shard its part of a request
before it waits for any reply (``request_sample``), and keeps every rule of one replay server:

- **Uniform sampling over the union.** A request's rows are split over the shards in proportion
  to how many items each one samples over (``info["live"]`` of its last reply; equal shares until
  every shard has answered once), and each shard draws uniformly from its own items; each item is
  then as likely as in one table. The rows are shuffled after merging, so every minibatch of a
  ``num_batches`` request mixes the shards.
- **Retention's demo share.** Each shard keeps its own demo region of ``demo_ratio`` of its
  capacity; sampling in proportion to each shard's items (demo rows included) keeps the union's
  demo share at ``demo_ratio``.
- **Priorities.** Prioritized shards are split in proportion to their priority mass (``mass``),
  so an item's probability is its priority over the total mass of all shards, as in one sum tree.
  Each shard's importance weights ``(N_j p / M_j)^-beta`` are turned into the union's
  ``(N p / M)^-beta`` (N, M: all shards' items and mass) and normalised by the request's maximum.
  Row keys are returned as ``key * N + shard`` so the priority update of each row goes back to the
  shard that sampled it (``send_priorities`` splits the update).
- **Refusals.** A shard that refuses (its rate limiter, not enough items yet) or does not answer
  leaves its rows to the others: the request is served with the whole batches the answering
  shards' rows make, and the rows beyond the last whole batch are dropped and counted
  (``discarded_rows``). The rate limiters stay per shard: a shard whose workers insert faster
  refuses less and is sampled more, which keeps each shard's ratio near the target. A sync-mode
  request (``min_version``) is served only when every shard serves it.

The weights are one reply old (the sizes and masses come with each shard's previous batch); a
shard's proportion moves by its inserts between two requests, a few rows in thousands.

Room: learner (component). May import: the contract and laneshift.learner (``seams``); never another component.
"""

from __future__ import annotations

import concurrent.futures
import threading
from typing import Sequence

import numpy as np

from laneshift import wire
from laneshift.replay_stats import merge_replay_stats

from .seams import ReplayClient, ReplayShardClient


def split_rows(rows: int, weights: Sequence[float]) -> list[int]:
    """``rows`` split in proportion to ``weights`` (largest remainder; zero weight: zero rows).

    >>> split_rows(10, [1, 1, 2])
    [3, 2, 5]
    """
    w = np.asarray(weights, np.float64)
    if w.sum() <= 0:
        w = np.ones_like(w)
    exact = rows * w / w.sum()
    counts = np.floor(exact).astype(np.int64)
    short = rows - int(counts.sum())
    if short:
        counts[np.argsort(-(exact - counts), kind="stable")[:short]] += 1
    return [int(c) for c in counts]


def replay_over(shards: Sequence[ReplayShardClient], beta: float = 0.4, seed: int = 0) -> ReplayClient:
    """The learner's ``ReplayClient`` for ``shards``: the one client itself, or ``ShardedReplay``
    over several (``beta``, ``seed``: its importance weights and row shuffle)."""
    return shards[0] if len(shards) == 1 else ShardedReplay(shards, beta=beta, seed=seed)


class ShardedReplay:
    """A ``ReplayClient`` over one ``ReplayShardClient`` per shard (see the module's text)."""

    def __init__(self, shards: Sequence[ReplayShardClient], beta: float = 0.4, seed: int = 0):
        if len(shards) < 2:
            raise ValueError("ShardedReplay needs at least 2 shards; use the one client itself")
        self.shards, self.n, self.beta = list(shards), len(shards), beta
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()  # the sizes, masses and counters below
        self.live: list[int | None] = [None] * self.n  # items each shard sampled over at its last reply
        self.mass: list[float | None] = [None] * self.n  # its priority mass (prioritized replay)
        self.discarded_rows = 0  # rows drawn but beyond the last whole batch when a shard refused
        self.partial_requests = 0  # requests served by some shards only
        # Stats and control commands to every shard at once (a few a second; samples need no pool).
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=self.n, thread_name_prefix="replay-shard")

    # ------------------------------------------------------------------ sampling

    def _weights(self) -> list[float]:
        """Each shard's share of a request: its priority mass, else its item count; a shard not
        heard from yet gets the mean of the others (equal shares at the start)."""
        with self._lock:
            known = self.mass if all(m is not None for m in self.mass) else self.live
            seen = [float(k) for k in known if k is not None]
            mean = sum(seen) / len(seen) if seen else 1.0
            return [float(k) if k is not None else mean for k in known]

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch | wire.WireError | None:
        rows = req.batch_size * req.num_batches
        counts = split_rows(rows, self._weights())
        asks = {i: wire.SampleRequest(c, 1, req.min_version,
                                      tuple(a for a in req.actors if wire.shard_of(a, self.n) == i), req.next_obs)
                for i, c in enumerate(counts) if c > 0}
        # Every shard is asked before any reply is awaited, all from this thread: the replies come
        # in together while this thread waits, with no pool threads to wake or to take the GIL.
        pending = {i: self.shards[i].request_sample(ask) for i, ask in asks.items()}
        replies = {i: wait() for i, wait in pending.items()}
        served = {i: r for i, r in replies.items() if isinstance(r, wire.SampledBatch)}
        refused = [r for r in replies.values() if not isinstance(r, wire.SampledBatch)]
        with self._lock:
            for i, batch in served.items():
                self.live[i] = int(batch.info.get("live", self.live[i] or 0))
                if "mass" in batch.info:
                    self.mass[i] = float(batch.info["mass"])
        got = sum(len(b.action) for b in served.values())
        whole = got // req.batch_size
        if refused and (req.min_version >= 0 or whole == 0):
            with self._lock:
                self.discarded_rows += got
            return _first_refusal(refused)
        if refused:
            with self._lock:
                self.partial_requests += 1
                self.discarded_rows += got - whole * req.batch_size
        return self._merge(served, whole * req.batch_size, whole)

    def _merge(self, served: dict[int, wire.SampledBatch], rows: int, num_batches: int) -> wire.SampledBatch:
        parts = [(i, served[i]) for i in sorted(served)]
        cat = {name: np.concatenate([getattr(b, name) for _, b in parts])
               for name in ("obs", "action", "reward", "next_obs", "terminated", "steps", "is_demo")
               if all(getattr(b, name) is not None for _, b in parts)}  # next_obs: none where not asked for
        index = np.concatenate([b.index * self.n + i for i, b in parts])
        weight = np.concatenate([self._union_weights(i, b) for i, b in parts]).astype(np.float32)
        weight /= max(float(weight.max()), 1e-12)
        order = self._rng.permutation(len(index))[:rows]  # mix the shards in every minibatch
        info = dict(parts[0][1].info)
        info["live"] = sum(int(b.info.get("live", 0)) for _, b in parts)
        info["shards"] = [i for i, _ in parts]
        return wire.SampledBatch(**{k: v[order] for k, v in cat.items()}, index=index[order],
                                 weight=weight[order], num_batches=num_batches, info=info)

    def _union_weights(self, shard: int, batch: wire.SampledBatch) -> np.ndarray:
        """Shard ``shard``'s importance weights as weights of one draw over every shard."""
        if "mass" not in batch.info:
            return np.ones(len(batch.action), np.float64)
        with self._lock:
            live_all = sum(x or 0 for x in self.live)
            mass_all = sum(x or 0.0 for x in self.mass)
        live, mass = int(batch.info["live"]), float(batch.info["mass"])
        raw = batch.weight.astype(np.float64) * float(batch.info.get("weight_scale", 1.0))
        if live <= 0 or mass_all <= 0 or mass <= 0:
            return raw
        return raw * ((live_all * mass) / (live * mass_all)) ** -self.beta

    # ------------------------------------------------------------------ the rest of ReplayClient

    def send_priorities(self, update: wire.PriorityUpdate) -> None:
        """Split a priority update by the shard each row came from (``key * N + shard``)."""
        shard = update.index % self.n
        for i in range(self.n):
            mine = shard == i
            if mine.any():
                self.shards[i].send_priorities(wire.PriorityUpdate(
                    index=update.index[mine] // self.n, is_demo=update.is_demo[mine],
                    priority=update.priority[mine]))

    def replay_stats(self) -> dict | None:
        """Every shard's stats as one (``replay_stats.merge_replay_stats``); None unless all answered."""
        bodies = list(self._pool.map(lambda s: s.replay_stats(), self.shards))
        if any(b is None for b in bodies):
            return None
        merged = merge_replay_stats(bodies)
        with self._lock:
            merged["sharded_sampling"] = {"discarded_rows": self.discarded_rows,
                                          "partial_requests": self.partial_requests}
        return merged

    def set_phase(self, phase: int) -> bool:
        """Every shard to ``phase``: True only when every shard took it."""
        return all(list(self._pool.map(lambda s: s.set_phase(phase), self.shards)))

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


def _first_refusal(refused: list) -> wire.WireError | None:
    """What to tell the learner when the request cannot be served: the refusal that asks for the
    shortest wait (None, 'no answer', only when no shard answered at all)."""
    errors = [r for r in refused if isinstance(r, wire.WireError)]
    if not errors:
        return None
    return min(errors, key=lambda e: getattr(e, "retry_after_ms", 0))
