"""The replay core's book of actors (``ActorLedger``, a base of ``core.ReplayCore``): each actor's
counters and row index, admitted on its first batch and, past ``MAX_ACTORS``, the one idle longest
evicted (its counters remembered, so one that comes back continues them), with a place always kept
for each of the run's own env workers; the seqs counted lost that
a resend may still fill (``gaps.Gaps``); what a restarted actor resumes from (``actor_state``,
``delivery_state``); the pages of per-actor stats; and a checkpoint's actors taken back.

The state lives on the core (``actors``, ``actor_index``, ``gaps``, ``evicted_total`` and the private
lists ``init_ledger`` makes); the methods marked so run under the core's ``lock``.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Iterable
from typing import Any

from laneshift.config import ReplayConfig

from .frames import FrameRingTable
from .gaps import Gaps
from .storage import RingTable

MAX_ACTORS = 4096
#: Evicted actors remembered (name -> their state) so one that comes back continues its counts;
#: an actor evicted from this too is new when it returns, and its earlier batches read as lost
#: (over-counted, never hidden).
MAX_EVICTED = 4 * MAX_ACTORS
#: Actors in one page of ``actor_page`` (control ``{"cmd": "actors"}``, HTTP ``/actors``).
MAX_ACTOR_PAGE = 256
#: The per-actor counters summed over every actor, evicted ones included (``actors_total``).
SUMMED = ("batches", "items", "stored", "lost_batches", "lost_items", "env_steps", "duplicates")


class ActorLedger:
    """Per-actor state of a replay core; ``init_ledger`` makes it, ``core.ReplayCore`` uses it."""

    cfg: ReplayConfig
    lock: threading.Lock
    online: RingTable | FrameRingTable

    def init_ledger(self, own_actors: Iterable[str] = ()) -> None:
        # The run's own env workers: a place each is kept for them, so that other names, however
        # many (a foreign client, a misconfigured fleet), can never lock out a worker that joins
        # late; without it a late worker's every batch was refused and the run stalled.
        self.own_actors = frozenset(own_actors)
        self.actors: dict[str, dict[str, int]] = {}
        self.actor_index: dict[str, int] = {}  # actor -> its row index in the online table's actor column
        self._free_indices: collections.deque[int] = collections.deque()  # of evicted actors, reused
        self._last_seen: dict[str, float] = {}  # actor -> monotonic time of its newest batch
        self._evicted: collections.OrderedDict[str, dict[str, int]] = collections.OrderedDict()
        self.evicted_total: collections.Counter[str] = collections.Counter()  # counters of evicted actors
        # Seqs counted lost that a worker may still send (its resend window): taken, they are no
        # longer lost. Per actor; only actors with such seqs have an entry.
        self.gaps: dict[str, Gaps] = {}

    def _fill_gap(self, actor: str, stats: dict[str, int], seq: int, n: int) -> bool:
        """A batch with ``seq`` below the actor's newest: if it is one counted lost (a gap still
        tracked), it is no longer lost (called under the lock); else False (a duplicate)."""
        gaps = self.gaps.get(actor)
        if gaps is None:
            return False
        released = gaps.fill(seq, n)
        if released is None:
            return False
        stats["lost_batches"] -= 1
        stats["lost_items"] -= released
        if not gaps.missing:
            del self.gaps[actor]
        return True

    def missing(self, actor: str, from_seq: int = 0) -> list[int]:
        """The seqs of ``actor`` counted lost that would still be taken (newest MISSING_KEPT at
        most), from ``from_seq`` on."""
        with self.lock:
            gaps = self.gaps.get(actor)
            return [s for s in gaps.missing if s >= from_seq] if gaps is not None else []

    def _admit(self, actor: str) -> dict[str, int] | None:
        """State for an actor not in the table (called under the lock): its remembered state if it
        was evicted, else fresh. Names other than ``own_actors`` share MAX_ACTORS less the places
        kept for those; when theirs are taken, the other actor idle longest is evicted first, if
        idle for ``replay.actor_idle_evict_s``; None if none is (the batch is refused)."""
        if actor in self.own_actors:
            if len(self.actors) >= MAX_ACTORS:  # only after a restore from a run with fewer places kept
                self._evict(self._idle_longest_other())
        elif len(self.actors) - sum(a in self.actors for a in self.own_actors) >= MAX_ACTORS - len(self.own_actors):
            oldest = self._idle_longest_other()
            if oldest is None or time.monotonic() - self._last_seen[oldest] < self.cfg.actor_idle_evict_s:
                return None
            self._evict(oldest)
        stats = self._evicted.pop(actor, None)
        if stats is not None:
            for key, value in stats.items():  # its counters come back out of the evicted totals
                if key in SUMMED:
                    self.evicted_total[key] -= value
            self.evicted_total["count"] -= 1
        else:
            stats = {"batches": 0, "items": 0, "stored": 0, "last_seq": -1, "lost_batches": 0, "lost_items": 0,
                     "last_version": -1, "env_steps": 0, "duplicates": 0}
        self.actor_index[actor] = self._free_indices.popleft() if self._free_indices else len(self.actor_index)
        self.actors[actor] = stats
        return stats

    def _idle_longest_other(self) -> str | None:
        """The actor other than ``own_actors`` whose newest batch is oldest (None: there is none)."""
        others = (a for a in self._last_seen if a not in self.own_actors)
        return min(others, key=self._last_seen.__getitem__, default=None)

    def _evict(self, actor: str) -> None:
        """Move an idle actor's state out of the live table (called under the lock); its counters
        stay in the totals, and its row index goes to the next new actor."""
        stats = self.actors.pop(actor)
        index = self.actor_index.pop(actor)
        self._free_indices.append(index)
        if isinstance(self.online, FrameRingTable):
            self.online.forget_actor(index)
        self._last_seen.pop(actor, None)
        self.gaps.pop(actor, None)  # an idle actor resends nothing: its gaps stay lost
        self._evicted[actor] = stats
        for key in SUMMED:
            self.evicted_total[key] += int(stats.get(key, 0))
        self.evicted_total["count"] += 1
        self.evicted_total["evictions"] += 1
        if len(self._evicted) > MAX_EVICTED:
            self._evicted.popitem(last=False)  # forgotten: its counters stay in evicted_total

    def evicted_stats(self) -> dict[str, dict[str, int]]:
        """The remembered counters of evicted actors (call under ``lock``): for checkpoints."""
        return {name: dict(stats) for name, stats in self._evicted.items()}

    def restore_actors(self, actors: dict[str, dict[str, int]], index: dict[str, int],
                       evicted: dict[str, dict[str, int]], evicted_total: dict[str, int],
                       gaps: dict[str, Any] | None = None) -> None:
        """Take back the actors' state from a checkpoint (call under ``lock``, on a fresh core):
        their counters, row indices (unused ones free for new actors), the evicted actors'
        counters, the gaps still fillable. Every restored actor counts as seen now."""
        self.actors.update({k: {"lost_items": 0, "duplicates": 0, **v} for k, v in actors.items()})
        self.gaps.update({k: Gaps.from_json(v) for k, v in (gaps or {}).items() if k in self.actors})
        self.actor_index.update(index)
        used = set(index.values())
        self._free_indices.extend(i for i in range(len(index)) if i not in used)
        now = time.monotonic()
        for name in self.actors:
            self._last_seen[name] = now
        for name, stats in evicted.items():
            self._evicted[name] = dict(stats)
        self.evicted_total.update({k: int(v) for k, v in evicted_total.items()})


    def actor_state(self, actor: str) -> dict[str, int]:
        """An actor's progress as this server knows it: ``env_steps`` of its newest batch and the
        ``next_seq`` it should send. A restarted actor resumes there, so its budget is neither
        spent twice nor lost, and its sequence numbers go on (gaps are counted as lost)."""
        with self.lock:
            stats = self.actors.get(actor)
            if stats is None and actor in self._evicted:
                stats = self._evicted[actor]
            if stats is None:
                return {"env_steps": 0, "next_seq": 0, "known": 0}
            return {"env_steps": int(stats["env_steps"]), "next_seq": int(stats["last_seq"]) + 1, "known": 1}

    def delivery_state(self, actor: str, from_seq: int = 0) -> dict[str, Any]:
        """What a worker needs to resend what this server lacks: ``actor_state`` plus ``missing``
        (its seqs from ``from_seq`` on counted lost that would still be taken) and ``server`` (this
        process's id: a new one means whatever was on its way to the old one may be gone)."""
        state: dict[str, Any] = dict(self.actor_state(actor))
        state["missing"] = self.missing(actor, from_seq)
        state["server"] = self.incarnation
        return state

    def actor_page(self, offset: int = 0, limit: int = MAX_ACTOR_PAGE) -> dict[str, Any]:
        """Per-actor stats, ``limit`` (at most MAX_ACTOR_PAGE) actors from ``offset`` in name order."""
        offset, limit = max(0, int(offset)), max(1, min(int(limit), MAX_ACTOR_PAGE))
        with self.lock:
            names = sorted(self.actors)[offset:offset + limit]
            return {"total": len(self.actors), "offset": offset,
                    "actors": {n: dict(self.actors[n]) for n in names}}


    def _actors_total(self) -> dict[str, int]:
        """Sums over every actor, evicted ones included (called under the lock)."""
        total = {k: sum(int(a.get(k, 0)) for a in self.actors.values()) + self.evicted_total[k] for k in SUMMED}
        versions = [int(a["last_version"]) for a in self.actors.values()]
        return {"count": len(self.actors), **total, "min_version": min(versions, default=-1),
                "max_version": max(versions, default=-1), "evicted": self.evicted_total["count"],
                "evictions": self.evicted_total["evictions"]}
