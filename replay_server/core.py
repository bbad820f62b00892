"""The replay server's state and rules, free of any transport (zenoh lives in service.py).

``ReplayCore`` ingests encoded transition batches, answers encoded sample requests and
reports stats. It is thread-safe: the zenoh service calls it from its ingest and query
threads, unit tests call it directly.

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
from typing import Any

import numpy as np

from laneshift.config import ReplayConfig
from laneshift.wire import (WIRE_VERSION, PriorityUpdate, SampledBatch, SampleRequest, TransitionSchema,
                            WireError, decode_priorities, decode_sample_request, decode_transitions, encode_batch,
                            encode_error)

from .frames import FrameRingTable
from .rate_limiter import SampleToInsertRatio
from .selectors import PrioritizedSelector, UniformSelector
from .storage import DemoTable, RingTable

MAX_ACTORS = 4096
#: Evicted actors remembered (name -> their state) so one that comes back continues its counts;
#: an actor evicted from this too is new when it returns, and its earlier batches read as lost
#: (over-counted, never hidden).
MAX_EVICTED = 4 * MAX_ACTORS
#: Actors listed in a stats reply: the reply stays the same size whatever the number of actors
#: (at ~650 actors the full list outgrew the wire's 64 KiB JSON limit and broke every stats query).
#: ``actors_total`` sums all of them; ``actor_page`` (control ``{"cmd": "actors"}``, HTTP
#: ``/actors``) pages through the rest.
ACTORS_IN_STATS = 32
MAX_ACTOR_PAGE = 256


class ReplayCore:
    def __init__(self, cfg: ReplayConfig, schema: TransitionSchema, demo: DemoTable | None = None):
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
        self.actors: dict[str, dict[str, int]] = {}
        self.actor_index: dict[str, int] = {}  # actor -> its row index in the online table's actor column
        self._free_indices: collections.deque[int] = collections.deque()  # of evicted actors, reused
        self._last_seen: dict[str, float] = {}  # actor -> monotonic time of its newest batch
        self._evicted: collections.OrderedDict[str, dict[str, int]] = collections.OrderedDict()
        self.evicted_total: collections.Counter[str] = collections.Counter()  # counters of evicted actors
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
        # Seqs counted lost that a worker may still send (its resend window): taken, they are no
        # longer lost. Per actor; only actors with such seqs have an entry.
        self.gaps: dict[str, Gaps] = {}
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
        was evicted, else fresh. At MAX_ACTORS the actor idle longest is evicted first, if idle for
        ``replay.actor_idle_evict_s``; None if none is (the batch is refused)."""
        if len(self.actors) >= MAX_ACTORS:
            oldest = min(self._last_seen, key=self._last_seen.__getitem__, default=None)
            if oldest is None or time.monotonic() - self._last_seen[oldest] < self.cfg.actor_idle_evict_s:
                return None
            self._evict(oldest)
        stats = self._evicted.pop(actor, None)
        if stats is not None:
            for key, value in stats.items():  # its counters come back out of the evicted totals
                if key in _SUMMED:
                    self.evicted_total[key] -= value
            self.evicted_total["count"] -= 1
        else:
            stats = {"batches": 0, "items": 0, "stored": 0, "last_seq": -1, "lost_batches": 0, "lost_items": 0,
                     "last_version": -1, "env_steps": 0, "duplicates": 0}
        self.actor_index[actor] = self._free_indices.popleft() if self._free_indices else len(self.actor_index)
        self.actors[actor] = stats
        return stats

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
        for key in _SUMMED:
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

    # ------------------------------------------------------------------ sampling

    def sample(self, req: SampleRequest) -> SampledBatch | WireError:
        """Draw ``req.num_batches * req.batch_size`` rows, or say why not (rate limited, not ready)."""
        rows = req.batch_size * req.num_batches
        try:
            self.limiter.check_request(rows)
        except ValueError as exc:
            return _retry("request_too_large", str(exc), 0)
        with self.lock:
            if req.min_version >= 0:
                behind = [a for a in req.actors if self.actors.get(a, {}).get("last_version", -1) < req.min_version]
                if behind:
                    self.requests["not_ready"] += 1
                    return _retry("not_ready", f"waiting for {behind} to deliver version {req.min_version}", 2)
            demo_only = self.phase == 1
            if demo_only:
                n_demo, n_online = self.demo.size, 0
            else:
                if not self.limiter.can_sample(size=self.online.size, inserts=self.online.inserted,
                                               samples=self.samples, rows=rows):
                    self.requests["rate_limited"] += 1
                    return _retry("rate_limited", f"online size {self.online.size}, min {self.limiter.min_size}", 5)
                n_demo = self.demo.size if self.cfg.retains_demos else 0
                n_online = self.online.size
            drawn = self.selector.draw(self._rng, rows, n_demo, self.online.tail, n_online, self.online.capacity)
            is_demo = drawn.is_demo
            batch = self._gather(is_demo, drawn.demo_rows, drawn.online_rows, req.num_batches, drawn.weight)
            # How many items this draw was over (and, prioritized, their mass and the weights'
            # scale): a learner sampling several shards weighs each by these (learner/shards.py).
            batch.info["live"] = n_demo + n_online
            if self.prioritized:
                batch.info.update(mass=drawn.mass, weight_scale=drawn.scale)
            if not demo_only:
                self.samples += rows
            demo_rows = len(drawn.demo_rows)
            self.sampled_rows += rows
            self.sampled_demo_rows += demo_rows
            self._recent.append((rows, demo_rows))
            self.requests["served"] += 1
            self._rates.add("samples", rows)
        return batch

    def _gather(self, is_demo: np.ndarray, demo_rows: np.ndarray, online_rows: np.ndarray, nb: int,
                weight: np.ndarray) -> SampledBatch:
        n = is_demo.shape[0]
        index = np.empty(n, np.int64)
        info = {"phase": self.phase, "prioritized": self.prioritized}
        records = self.online.records
        if demo_rows.shape[0] == 0 and records is not None:
            # All rows online, in a record table: one gather of whole records (storage.record_dtype).
            # The batch's columns are views of it; encode_batch copies each once, into the reply.
            picked = np.take(records, online_rows, mode="clip")
            _take(self.online.key, online_rows, index)
            return SampledBatch(obs=picked["obs"], action=picked["action"], reward=picked["reward"],
                                next_obs=picked["next_obs"], terminated=picked["terminated"], steps=picked["steps"],
                                is_demo=is_demo.view(np.uint8), index=index, weight=weight, num_batches=nb, info=info)
        out = {
            "obs": np.empty((n, *self.schema.obs_shape), self.schema.obs_dtype),
            "next_obs": np.empty((n, *self.schema.obs_shape), self.schema.obs_dtype),
            "action": np.empty(n, np.int64), "reward": np.empty(n, np.float32), "terminated": np.empty(n, np.uint8),
            "steps": np.empty(n, np.uint8),
        }
        if demo_rows.shape[0] == 0:  # all rows online (no demos sampled): gather straight into the outputs
            for name, arr in out.items():
                _take(getattr(self.online, name), online_rows, arr)
            _take(self.online.key, online_rows, index)
        else:
            d, o = is_demo, ~is_demo
            picked = np.take(records, online_rows, mode="clip") if records is not None else None
            for name in out:
                out[name][d] = getattr(self.demo, name)[demo_rows]
                out[name][o] = picked[name] if picked is not None else getattr(self.online, name)[online_rows]
            index[d] = demo_rows
            index[o] = self.online.key[online_rows]
        return SampledBatch(is_demo=is_demo.astype(np.uint8), index=index, weight=weight, num_batches=nb, info=info,
                            **out)

    def update_priorities(self, update: PriorityUpdate) -> int:
        """New priorities for sampled items (e.g. |TD error|); items evicted since are skipped.

        Returns how many leaves changed. Demo items get ``demo_priority_bonus`` on top (DQfD).
        """
        if not self.prioritized:
            return 0
        cfg = self.cfg
        with self.lock:
            raw = update.priority.astype(np.float64) + cfg.priority_eps
            demo = update.is_demo.astype(bool)
            raw[demo] += cfg.demo_priority_bonus
            demo_live = self.demos_sampled
            ok_demo = demo & (update.index < self.demo.size) & demo_live
            rows = update.index % self.online.capacity
            # Not overwritten (nor dropped with its frames) since sampled.
            ok_online = ~demo & (self.online.key[rows] == update.index) & (update.index >= self.online.tail)
            changed = self.selector.update(update.index[ok_demo], raw[ok_demo], rows[ok_online], raw[ok_online])
            self.priority_updates += 1
            return changed

    def handle_priorities(self, payload: bytes | bytearray | memoryview) -> str | None:
        """Bytes in: apply a PRIORITIES message, or count why it was refused (never raises)."""
        try:
            self.update_priorities(decode_priorities(payload))
        except WireError as exc:
            return self.reject("priorities:" + exc.reason)
        except Exception:  # noqa: BLE001
            return self.reject("priorities:failed")
        return None

    def handle_sample_query(self, payload: bytes | bytearray | memoryview) -> bytes | bytearray:
        """Bytes in, bytes out: what the zenoh queryable replies."""
        # A learner sends the same request bytes every time: decode them once (SampleRequest is frozen).
        last = self._last_request
        if last is not None and payload == last[0]:
            req = last[1]
        else:
            try:
                req = decode_sample_request(payload)
            except WireError as exc:
                self.reject("bad_request:" + exc.reason)
                return encode_error("bad_request", exc.detail)
            self._last_request = (bytes(payload), req)
        result = self.sample(req)
        if isinstance(result, WireError):
            return encode_error(result.reason, result.detail, getattr(result, "retry_after_ms", 0))
        return encode_batch(result)

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

    def info(self, run_id: str | None) -> dict[str, Any]:
        """The body of ``replay/info`` over zenoh and of HTTP ``/info``: what a client needs to
        build TRANSITIONS (the wire version, observation shape and dtype, action count), with the
        run id it is served under, the demo mode and the HTTP API's URL."""
        schema = self.schema
        return {"wire_version": WIRE_VERSION, "obs_shape": list(schema.obs_shape), "obs_dtype": schema.obs_dtype,
                "n_actions": schema.n_actions, "run_id": run_id, "mode": self.mode, "http_url": self.http_url}

    def _actors_total(self) -> dict[str, int]:
        """Sums over every actor, evicted ones included (called under the lock)."""
        total = {k: sum(int(a.get(k, 0)) for a in self.actors.values()) + self.evicted_total[k] for k in _SUMMED}
        versions = [int(a["last_version"]) for a in self.actors.values()]
        return {"count": len(self.actors), **total, "min_version": min(versions, default=-1),
                "max_version": max(versions, default=-1), "evicted": self.evicted_total["count"],
                "evictions": self.evicted_total["evictions"]}

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


_SUMMED = ("batches", "items", "stored", "lost_batches", "lost_items", "env_steps", "duplicates")

#: Seqs counted lost that stay fillable, per actor: the newest this many (a worker holds at most
#: its MAX_IN_FLIGHT unacknowledged batches, 64, so older ones can never come).
MISSING_KEPT = 256


class Gaps:
    """One actor's seqs counted lost that may still arrive, with the items each gap was charged
    (from the actor's env steps). A batch that fills a seq takes its items off its gap's charge;
    the gap's last seq filled takes the rest, so a gap filled whole counts exactly 0 lost.

        >>> g = Gaps(); g.add(3, 6, 30)  # seqs 3, 4, 5: 30 items counted lost
        >>> g.fill(4, 10), g.fill(4, 10), g.missing
        (10, None, [3, 5])
        >>> g.fill(3, 10), g.fill(5, 8)
        (10, 10)
    """

    def __init__(self) -> None:
        self._seq_gap: dict[int, int] = {}  # missing seq -> its gap's first seq, ascending
        self._gap: dict[int, list[int]] = {}  # gap's first seq -> [items still charged, seqs still tracked]

    @property
    def missing(self) -> list[int]:
        return list(self._seq_gap)

    def add(self, first: int, end: int, charged: int) -> None:
        """Seqs ``first .. end - 1`` were skipped, ``charged`` items counted lost for them."""
        tracked = range(max(first, end - MISSING_KEPT), end)
        if not tracked:
            return
        self._gap[first] = [charged, len(tracked)]
        for s in tracked:
            self._seq_gap[s] = first
        while len(self._seq_gap) > MISSING_KEPT:  # the oldest stay lost for good
            s = next(iter(self._seq_gap))
            self._forget(s, self._seq_gap.pop(s))

    def fill(self, seq: int, n: int) -> int | None:
        """``seq`` arrived with ``n`` items: the items no longer lost, or None if it is not missing."""
        first = self._seq_gap.pop(seq, None)
        if first is None:
            return None
        gap = self._gap[first]
        gap[1] -= 1
        released = gap[0] if gap[1] == 0 else min(n, gap[0])
        gap[0] -= released
        if gap[1] == 0:
            del self._gap[first]
        return released

    def _forget(self, seq: int, first: int) -> None:
        gap = self._gap[first]
        gap[1] -= 1
        if gap[1] == 0:
            del self._gap[first]

    def to_json(self) -> dict[str, Any]:
        return {"missing": [[s, f] for s, f in self._seq_gap.items()],
                "gaps": [[f, c, t] for f, (c, t) in self._gap.items()]}

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> "Gaps":
        g = cls()
        g._gap = {int(f): [int(c), int(t)] for f, c, t in body.get("gaps", [])}
        g._seq_gap = {int(s): int(f) for s, f in sorted(body.get("missing", [])) if int(f) in g._gap}
        return g


def _take(column: Any, rows: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = column[rows]`` without the temporary: ``np.take(out=)`` for an array column
    (mode "clip": with the default "raise" numpy buffers ``out``; the rows come from the selector,
    in range by construction); a frame table's stacked view gathers itself."""
    if type(column) is np.ndarray:
        np.take(column, rows, axis=0, out=out, mode="clip")
    else:
        out[...] = column[rows]


def _retry(reason: str, detail: str, retry_ms: int) -> WireError:
    err = WireError(reason, detail)
    err.retry_after_ms = retry_ms  # type: ignore[attr-defined]
    return err


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
