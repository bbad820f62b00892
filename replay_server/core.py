"""The replay server's state and rules, free of any transport (zenoh lives in service.py).

``ReplayCore`` ingests encoded transition batches, answers encoded sample requests and
reports stats. It is thread-safe: the zenoh service calls it from its ingest and query
threads, unit tests call it directly. This module holds its tables, ingest, control commands
and stats; its two bases hold the rest: ``actor_ledger.ActorLedger`` (per-actor counters,
eviction, the gaps a resend may fill) and ``sampling.Sampling`` (drawing and gathering batches,
priority updates).

The paper's three demo modes decide what is sampled:

- ``none``: the online FIFO table only; the demo shard (if any) is held but not sampled.
- ``retention``: ``round(demo_ratio * capacity)`` demo items are a fixed region of the buffer,
  never evicted; the online FIFO gets the rest of the capacity; sampling is uniform over both,
  so once the online part is full the demo share of batches equals ``demo_ratio``.
- ``rehearsal``: phase 1 samples the whole demo shard only and stores no agent transitions;
  after ``set_phase(2)`` (sent by the learner) it is ordinary replay on the online table.
- ``dqfd`` (beyond the paper, DQfD's pre-training): retention's buffer, with a phase 1 that
  samples its demo region only and stores no agent transitions, like rehearsal's.

    >>> from laneshift.config import ReplayConfig
    >>> from laneshift.wire import TransitionSchema
    >>> core = ReplayCore(ReplayConfig(capacity=100, min_size=10), TransitionSchema((3,), "float32", 9))
    >>> core.stats()["tables"]["online"]["size"]
    0

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import collections
import os
import threading
import time
from collections.abc import Iterable
from typing import Any

import numpy as np

from laneshift.config import ReplayConfig
from laneshift.wire import WIRE_VERSION, SampleRequest, TransitionSchema, WireError, decode_transitions

from .actor_ledger import MAX_ACTOR_PAGE, ActorLedger
from .frames import FrameRingTable
from .gaps import Gaps
from .rate_limiter import SampleToInsertRatio
from .sampling import Sampling
from .selectors import PrioritizedSelector, UniformSelector
from .storage import DemoTable, RingTable

#: Actors listed in a stats reply: the reply stays the same size whatever the number of actors
#: (at ~650 actors the full list outgrew the wire's 64 KiB JSON limit and broke every stats query).
#: ``actors_total`` sums all of them; ``actor_page`` (control ``{"cmd": "actors"}``, HTTP
#: ``/actors``) pages through the rest.
ACTORS_IN_STATS = 32


class ReplayCore(ActorLedger, Sampling):
    def __init__(self, cfg: ReplayConfig, schema: TransitionSchema, demo: DemoTable | None = None,
                 own_actors: Iterable[str] = ()):
        """``own_actors``: the run's own env workers' names, which always have a place in the
        book of actors, however many other names have arrived (actor_ledger.py)."""
        self.cfg = cfg
        self.schema = schema
        self._rng = np.random.default_rng(cfg.seed)
        # Held by every public method. Hold it (``with core.lock:``) to read several fields at one
        # instant: the checkpointer and the HTTP API do.
        self.lock = threading.Lock()
        self.mode = cfg.demo_mode
        held = demo if demo is not None else DemoTable.empty(schema.obs_shape, schema.obs_dtype)
        self.demo_held = held  # everything loaded, for stats and inspection
        online_capacity = cfg.capacity
        if cfg.retains_demos:
            want = round(cfg.demo_ratio * cfg.capacity)
            if held.size < want:
                raise ValueError(
                    f"replay.demo_ratio: {self.mode} needs {want} demo transitions ({cfg.demo_ratio:.0%} of "
                    f"replay.capacity {cfg.capacity}) but the demo shard has {held.size}; record more demos "
                    f"or lower replay.capacity to {int(held.size / cfg.demo_ratio)}")
            # A fixed, seeded subset fills the demo region; it never changes during the run.
            rows = np.sort(self._rng.choice(held.size, size=want, replace=False))
            self.demo = held.subset(rows)
            online_capacity = cfg.capacity - want
        elif self.mode == "rehearsal":
            if held.size == 0:
                raise ValueError("replay.demo_paths: rehearsal phase 1 learns from demos only, but none were loaded")
            self.demo = held
        else:
            self.demo = DemoTable.empty(schema.obs_shape, schema.obs_dtype)
        self.phase = 1 if cfg.pretrains else 0
        if len(schema.obs_shape) == 3:  # stacked frames: each frame held once (frames.py)
            self.online = FrameRingTable(online_capacity, schema.obs_shape, schema.obs_dtype, cfg.frames_per_item)
        else:
            self.online = RingTable(online_capacity, schema.obs_shape, schema.obs_dtype)
        self.limiter = SampleToInsertRatio(cfg.samples_per_insert, cfg.min_size, online_capacity,
                                           cfg.spi_tolerance)
        self.started = time.monotonic()
        # Counters (all guarded by lock).
        self.rejected: collections.Counter[str] = collections.Counter()
        self.dropped: collections.Counter[str] = collections.Counter()
        self.init_ledger(own_actors)  # each actor's counters and row index, the evicted ones', the gaps (actor_ledger.py)
        self.samples = 0  # rows sampled while the rate limiter applies
        self.sampled_rows = 0
        self.sampled_demo_rows = 0
        self.requests = collections.Counter()
        self._recent = collections.deque(maxlen=200)  # (rows, demo rows) of recent requests
        self._rates = _RateMeter()
        self.last_checkpoint: dict = {}  # set by the service's checkpointer
        # Who this server serves ({"run_id", "config_digest"}); written into checkpoints and checked on restore.
        self.identity: dict[str, str] = {}
        self.checkpoint_failures = 0  # checkpoint writes that failed (full disk, read-only dir)
        # The write-ahead log (wal.WriteAheadLog, set by the server; None: none, as in unit tests):
        # the service writes each batch to it as it arrives; the core writes phase changes, and
        # its checkpoints cut it.
        self.wal = None
        self.wal_replayed: dict[str, int] = {}  # what the last start replayed from the log (wal.replay)
        # This process: a worker that sees it change sends again what it had not seen stored.
        self.incarnation = os.urandom(6).hex()
        self.http_url: str | None = None  # where this server's HTTP inspection API answers, if on
        # How rows are picked (selectors.py): uniform, or prioritized over [demo rows | online rows]
        # (demo leaves carry no mass in `none`, which has none, and from rehearsal's phase 2 on).
        self.selector: UniformSelector | PrioritizedSelector = (
            PrioritizedSelector(self.demo.size, self.online.capacity, cfg.priority_alpha, cfg.priority_beta,
                                cfg.demo_priority_bonus)
            if cfg.sampler == "prioritized" else UniformSelector())
        self.prioritized = self.selector.prioritized
        self.priority_updates = 0
        self._last_request: tuple[bytes, SampleRequest] | None = None  # handle_sample_query's cache

    # ------------------------------------------------------------------ ingest

    def ingest(self, payload: bytes | bytearray | memoryview, actor_key: str | None = None, *,
               replaying: bool = False) -> str | None:
        """Validate and store one transitions message. Returns None, or the reason it was refused.

        Never raises on bad input: a malformed message is counted by reason and dropped, and it
        is fully validated before anything is written, so no partial item can be stored. (The
        server's write-ahead log has it on disk before this is called: ``wal.py``.)

        ``replaying``: the message comes from the log at a restart (``wal.replay``): one whose seq
        the actor's counters already hold is skipped (``"duplicate"``), and one refused is not
        counted (it was when it first arrived): a replay never stores or counts a batch twice.
        """
        reject = (lambda reason: reason) if replaying else self.reject
        try:
            # Views of the payload, not copies: the ring copies them below, before this returns.
            batch = decode_transitions(payload, self.schema, copy=False)
        except WireError as exc:
            return reject(exc.reason)
        except Exception:  # noqa: BLE001 - a decoder bug must not take the server down
            return reject("decode_failed")
        if actor_key is not None and actor_key != batch.actor:
            return reject("actor_mismatch")
        n, seq, env_steps = len(batch), batch.seq, batch.env_steps
        with self.lock:
            stats = self.actors.get(batch.actor)
            if stats is None:
                stats = self._admit(batch.actor)
                if stats is None:
                    if not replaying:
                        self.rejected["too_many_actors"] += 1
                    return "too_many_actors"
            last_seq = stats["last_seq"]
            if seq <= last_seq and not self._fill_gap(batch.actor, stats, seq, n):
                # Held already (a worker's resend that crossed the original, a log record the
                # checkpoint holds): nothing stored or counted twice. Not an error.
                if not replaying:
                    stats["duplicates"] = stats.get("duplicates", 0) + 1
                return "duplicate"
            now = time.monotonic()
            self._last_seen[batch.actor] = now
            if seq > last_seq + 1:
                # A gap in seq: batches lost in transit, or stored by a server that died before its
                # checkpoint. An actor first seen at seq k > 0 lost its first k batches here (a
                # restarted server with no checkpoint), so last_seq starts at -1, not "unknown".
                stats["lost_batches"] += seq - last_seq - 1
                # Items in the gap: the actor's env steps between its last stored batch and this one.
                charged = max(0, env_steps - n - stats["env_steps"])
                stats["lost_items"] += charged
                # Its seqs stay fillable: a worker that still holds them sends them again.
                self.gaps.setdefault(batch.actor, Gaps()).add(last_seq + 1, seq, charged)
            if seq > last_seq:
                stats["last_seq"] = seq
            stats["batches"] += 1
            stats["items"] += n
            if batch.weights_version > stats["last_version"]:
                stats["last_version"] = batch.weights_version
            if env_steps > stats["env_steps"]:
                stats["env_steps"] = env_steps
            if self.cfg.pretrains and (self.phase == 1 or batch.phase == 1):
                # Paper: in phase 1 the agent's own transitions are not stored.
                self.dropped[f"{self.mode}_phase1"] += n
            else:
                tail = self.online.tail
                keys = self.online.insert(batch, self.actor_index[batch.actor])
                self.selector.stored(self.online, tail, keys)
                stats["stored"] += n
                self._rates.add("inserts", n, now)
        return None

    def count_restored_as_sampled(self) -> None:
        """The items restored (checkpoint, log) count as already sampled at the configured ratio:
        counting them as fresh inserts with no samples froze the actors for 10-33 s after a
        restart, waiting for the learner to "catch up" on data it had long learned from."""
        with self.lock:
            self.samples = int(max(0, self.online.inserted - self.cfg.min_size) * self.cfg.samples_per_insert)

    def reject(self, reason: str) -> str:
        """Count a message refused (here or by the service before it reached the core)."""
        with self.lock:
            self.rejected[reason] += 1
        return reason

    # ------------------------------------------------------------------ control and stats

    @property
    def demos_sampled(self) -> bool:
        """The demo table is part of what is sampled now: always in retention and dqfd's phase 2,
        and in the demo-only phase 1 of rehearsal and dqfd."""
        return self.cfg.retains_demos or self.phase == 1

    def set_phase(self, phase: int) -> None:
        if not self.cfg.pretrains or phase not in (1, 2):
            raise ValueError(f"phase {phase} is not valid in demo_mode {self.mode}")
        with self.lock:
            if phase < self.phase:
                raise ValueError("rehearsal phases only move forward")
            if phase == 2 and not self.cfg.retains_demos:
                self.selector.demos_off()  # ordinary replay now
            if phase != self.phase and self.wal is not None and self.wal.enabled:
                self.wal.write_phase(phase)  # a restart replays it between the batches around it
            self.phase = phase

    def insert_allowed(self) -> bool:
        """False while the learner is too far behind the ratio (actors wait; see rate_limiter)."""
        with self.lock:
            if self.phase == 1:
                return True
            return self.limiter.can_insert(inserts=self.online.inserted, samples=self.samples)

    def handle_control(self, body: dict[str, Any]) -> dict[str, Any]:
        cmd = body.get("cmd")
        try:
            if cmd == "set_phase":
                self.set_phase(int(body.get("phase", 0)))
                return {"ok": True, "phase": self.phase}
            if cmd == "stats":
                return {"ok": True, "stats": self.stats()}
            if cmd == "actors":  # a page of per-actor stats (stats lists only the first few)
                return {"ok": True, **self.actor_page(body.get("offset", 0), body.get("limit", MAX_ACTOR_PAGE))}
            if cmd == "actor_state":  # where a restarted actor resumes: its stored steps and next seq
                actor = str(body.get("actor", ""))
                if "from_seq" in body:  # a worker's acknowledgement query: also what to send again
                    return {"ok": True, **self.delivery_state(actor, int(body["from_seq"]))}
                return {"ok": True, **self.actor_state(actor)}
        except (TypeError, ValueError) as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": False, "error": f"unknown command {cmd!r}"}

    def info(self, run_id: str | None) -> dict[str, Any]:
        """The body of ``replay/info`` over zenoh and of HTTP ``/info``: what a client needs to
        build TRANSITIONS (the wire version, observation shape and dtype, action count), with the
        run id it is served under, the demo mode and the HTTP API's URL."""
        schema = self.schema
        return {"wire_version": WIRE_VERSION, "obs_shape": list(schema.obs_shape), "obs_dtype": schema.obs_dtype,
                "n_actions": schema.n_actions, "run_id": run_id, "mode": self.mode, "http_url": self.http_url}

    def _frame_stats(self) -> dict[str, Any]:
        """A frame table's frames: held, written, per item, and items dropped early for frames."""
        table = self.online
        if not isinstance(table, FrameRingTable):
            return {}
        return {"frames": {"capacity": table.store.capacity, "stored": table.frames_stored,
                           "per_item": round(table.frames_stored / table.inserted, 3) if table.inserted else None,
                           "evicted_for_frames": table.evicted_for_frames}}

    def stats(self, all_actors: bool = False) -> dict[str, Any]:
        """Counters of everything. ``actors`` lists the first ACTORS_IN_STATS actors by name
        (``all_actors`` lists all: for files and the in-process HTTP views, never for a reply)."""
        with self.lock:
            shown = sorted(self.actors) if all_actors else sorted(self.actors)[:ACTORS_IN_STATS]
            online_size = self.online.size
            demo_in_buffer = self.demo.size if self.demos_sampled else 0
            total = online_size + demo_in_buffer
            recent_rows = sum(r for r, _ in self._recent)
            recent_demo = sum(d for _, d in self._recent)
            return {
                "mode": self.mode,
                "phase": self.phase,
                "http_url": self.http_url,
                # What a TRANSITIONS message must carry (also on replay/info and HTTP /info).
                "obs_shape": list(self.schema.obs_shape), "obs_dtype": self.schema.obs_dtype,
                "n_actions": self.schema.n_actions,
                "uptime_s": round(time.monotonic() - self.started, 3),
                "tables": {
                    "online": {"size": online_size, "capacity": self.online.capacity, "inserted": self.online.inserted,
                               "bytes": self.online.nbytes, **self._frame_stats()},
                    "demo": {"size": self.demo.size, "held": self.demo_held.size, "sha256": self.demo_held.sha256,
                             "bytes": self.demo_held.nbytes},
                },
                "demo_in_buffer": demo_in_buffer,  # demo items sampled over now (merged over shards)
                "demo_share_buffer": (demo_in_buffer / total) if total and self.mode != "none" else 0.0,
                "demo_share_recent_samples": recent_demo / recent_rows if recent_rows else 0.0,
                "sampled_rows": self.sampled_rows,
                "sampled_demo_rows": self.sampled_demo_rows,
                "requests": dict(self.requests),
                "sampler": {"kind": self.cfg.sampler, "priority_updates": self.priority_updates,
                            "max_priority": self.selector.max_priority if self.prioritized else None},
                "rejected": dict(self.rejected),
                "dropped": dict(self.dropped),
                "actors": {k: dict(self.actors[k]) for k in shown},
                "actors_total": self._actors_total(),
                "rates": self._rates.rates(),
                "wal": ({**(self.wal.state() if self.wal is not None else {"mode": "off"}),
                         **({"replayed": dict(self.wal_replayed)} if self.wal_replayed else {})}),
                "checkpoint": {**self.last_checkpoint,
                               "age_s": round(time.monotonic() - self.last_checkpoint["monotonic"], 1),
                               "failures": self.checkpoint_failures}
                if self.last_checkpoint else ({"failures": self.checkpoint_failures} if self.checkpoint_failures else None),
                "rate_limiter": self.limiter.state(size=online_size, inserts=self.online.inserted,
                                                   samples=self.samples),
            }


class _RateMeter:
    """Events per second over a sliding window of a few seconds."""

    def __init__(self, window_s: float = 5.0):
        self.window_s = window_s
        self.events: dict[str, collections.deque] = collections.defaultdict(collections.deque)

    def add(self, name: str, count: int, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        q = self.events[name]
        q.append((now, count))
        while q and q[0][0] < now - self.window_s:
            q.popleft()

    def rates(self) -> dict[str, float]:
        now = time.monotonic()
        out = {}
        for name, q in self.events.items():
            recent = [c for t, c in q if t >= now - self.window_s]
            out[f"{name}_per_s"] = round(sum(recent) / self.window_s, 1)
        return out
