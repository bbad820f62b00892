"""The replay server process: ReplayCore behind zenoh.

- subscribes to ``laneshift/<run>/transitions/*``; a FIFO channel feeds one ingest thread, so
  a slow server back-pressures publishers (they use BLOCK) instead of losing data; with the
  write-ahead log (``replay.wal``, wal.py) a logger thread drains the channel, writes each batch
  to the log and queues it (``LOGGED_QUEUE``) for the ingest thread, so what arrived is on disk
  even while the ingest thread is behind;
- answers ``.../replay/sample`` (SampleRequest -> BATCH or ERROR), ``.../replay/stats`` (JSON),
  ``.../replay/control`` (JSON commands such as ``{"cmd": "set_phase", "phase": 2}``) and
  ``.../replay/info`` (JSON: the observation shape/dtype and action count TRANSITIONS must have).

Run it with ``laneshift replay-server --config run.yaml``.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import bisect
import json
import os
import queue
import shutil
import signal
import sys
import threading
import time
from pathlib import Path

import zenoh

from laneshift import transport, wire
from laneshift.config import SHIELD_DECEL, SHIELD_GAP, RunConfig, worker_names
from laneshift.envspec import EnvSpec

from . import wal as wal_log
from .checkpoint import CheckpointError, read_meta, restore_checkpoint, write_checkpoint
from .core import ReplayCore
from .demo_loading import load_demo_table


class SampleLatency:
    """Seconds the sample queryable spent per query (decode, sample, encode), in fixed buckets, by
    result (``batch`` or ``error``); the HTTP API's ``/metrics`` shows it as a histogram."""

    BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts = {r: [0] * (len(self.BUCKETS) + 1) for r in ("batch", "error")}  # last: above all buckets
        self._sums = {r: 0.0 for r in self._counts}

    def observe(self, result: str, seconds: float) -> None:
        with self._lock:
            self._counts[result][bisect.bisect_left(self.BUCKETS, seconds)] += 1
            self._sums[result] += seconds

    def snapshot(self) -> dict[str, tuple[list[int], float]]:
        """``{result: (per-bucket counts, the last one above every bucket), sum of seconds)}``."""
        with self._lock:
            return {r: (list(c), self._sums[r]) for r, c in self._counts.items()}


#: Batches logged but not yet applied, at most (then the logger waits, and back-pressure goes on
#: through the zenoh channel to the publishers). They are on disk: none is lost to a kill -9.
LOGGED_QUEUE = 256


class ReplayService:
    """Wires a ReplayCore to a zenoh session. ``start()`` returns at once; ``stop()`` joins."""

    def __init__(self, core: ReplayCore, session: zenoh.Session, run_id: str,
                 checkpoint_dir: Path | None = None, checkpoint_every_s: float = 0.0,
                 ingest_session: zenoh.Session | None = None, wal: wal_log.WriteAheadLog | None = None):
        self.core = core
        self.session = session
        # Transitions arrive on a session of their own, so a backlog of them (back-pressure) never
        # queues sample queries behind it.
        self.ingest_session = ingest_session or session
        self.run_id = run_id
        self.checkpoint_dir, self.checkpoint_every_s = checkpoint_dir, checkpoint_every_s
        # The write-ahead log checkpoints cut (rotate) and trim; it asks for one when it grows too big.
        self.wal = wal
        self.stop_event = threading.Event()
        self._logged: queue.Queue = queue.Queue(LOGGED_QUEUE)  # (actor, payload, on disk?) for the ingest thread
        # Wakes the checkpoint loop: the log's "too big" signal, or stop().
        self._wake = wal.checkpoint_due if self._wal_bounded else threading.Event()
        self._threads: list[threading.Thread] = []
        self._checkpoint_lock = threading.Lock()  # one checkpoint at a time (periodic vs final)
        # On the core, like http_url: the HTTP API (which gets only the core) reads it for /metrics.
        self.sample_latency = core.sample_latency = SampleLatency()

    def _sample(self, payload: bytes) -> bytes | bytearray:
        start = time.perf_counter()
        reply = self.core.handle_sample_query(payload)
        result = "batch" if wire.peek_kind(reply) == wire.Kind.BATCH else "error"
        self.sample_latency.observe(result, time.perf_counter() - start)
        return reply

    def start(self) -> "ReplayService":
        sub = self.ingest_session.declare_subscriber(wire.transitions_wildcard(self.run_id),
                                                     zenoh.handlers.FifoChannel(1024))
        if self.wal is not None and self.wal.enabled:  # received -> logged (logger) -> applied (ingest)
            logger = threading.Thread(target=self._drain, args=(sub, self._log), name="replay-wal", daemon=True)
            ingest = threading.Thread(target=self._apply_logged, name="replay-ingest", daemon=True)
            logger.start()
            self._threads.append(logger)
        else:
            ingest = threading.Thread(target=self._drain, args=(sub, self._ingest), name="replay-ingest", daemon=True)
        ingest.start()
        self._threads.append(ingest)
        prio_sub = self.session.declare_subscriber(wire.priorities_key(self.run_id), zenoh.handlers.FifoChannel(256))
        prio = threading.Thread(target=self._drain, name="replay-priorities", daemon=True,
                                args=(prio_sub, lambda sample: self.core.handle_priorities(sample.payload.to_bytes())))
        prio.start()
        self._threads.append(prio)
        if self.checkpoint_dir is not None and (self.checkpoint_every_s > 0 or self._wal_bounded):
            ckpt = threading.Thread(target=self._checkpoint_loop, name="replay-checkpoint", daemon=True)
            ckpt.start()
            self._threads.append(ckpt)
        flow = threading.Thread(target=self._flow_loop, name="replay-flow", daemon=True)
        flow.start()
        self._threads.append(flow)
        q = transport.serve_queries
        self._threads += [
            q(self.session, wire.sample_key(self.run_id), self._sample, self.stop_event, "replay-sample"),
            q(self.session, wire.replay_stats_key(self.run_id), lambda _: wire.encode_json(self.core.stats()),
              self.stop_event, "replay-stats"),
            q(self.session, wire.replay_control_key(self.run_id), self._control, self.stop_event, "replay-control"),
            q(self.session, wire.replay_info_key(self.run_id),
              lambda _: wire.encode_json(self.core.info(self.run_id)), self.stop_event, "replay-info"),
        ]
        return self

    def _drain(self, sub: zenoh.Subscriber, handle) -> None:
        """Feed every sample of ``sub`` to ``handle`` until stopped; a handler bug costs one message."""
        while not self.stop_event.is_set():
            try:
                sample = sub.recv()
            except Exception:  # noqa: BLE001 - channel closed with the session
                return
            try:
                handle(sample)
            except Exception:  # noqa: BLE001 - never let one message stop the thread
                self.core.reject("internal_error")

    def _ingest(self, sample: zenoh.Sample) -> None:
        try:
            actor = wire.actor_from_transitions_key(str(sample.key_expr))
        except ValueError:
            self.core.reject("bad_key")
            return
        self.core.ingest(sample.payload.to_bytes(), actor)

    def _log(self, sample: zenoh.Sample) -> None:
        """The logger thread: a received batch onto the log, then into the ingest thread's queue."""
        try:
            actor = wire.actor_from_transitions_key(str(sample.key_expr))
        except ValueError:
            self.core.reject("bad_key")
            return
        payload = sample.payload.to_bytes()
        item = (actor, payload, self.wal.write_transitions(actor, payload))
        while True:  # blocks while the queue is full (back-pressure); ends with the service
            try:
                self._logged.put(item, timeout=0.1)
                return
            except queue.Full:
                if self.stop_event.is_set():
                    return  # on disk: the next start replays it

    def _apply_logged(self) -> None:
        """The ingest thread with a log: apply each logged batch, then tell the log. Goes on after
        stop() until the queue is empty, so the final checkpoint has what was logged."""
        while True:
            try:
                actor, payload, logged = self._logged.get(timeout=0.1)
            except queue.Empty:
                if self.stop_event.is_set():
                    return
                continue
            try:
                self.core.ingest(payload, actor)
            except Exception:  # noqa: BLE001 - never let one message stop the thread
                self.core.reject("internal_error")
            finally:
                if logged:
                    self.wal.applied()
                self._logged.task_done()

    def drain(self, timeout_s: float) -> bool:
        """Wait (at most ``timeout_s``) until every logged batch is applied: before a final checkpoint."""
        deadline = time.monotonic() + timeout_s
        while self._logged.unfinished_tasks and time.monotonic() < deadline:
            time.sleep(0.01)
        return not self._logged.unfinished_tasks

    def _flow_loop(self, period_s: float = 0.01, heartbeat_s: float = 0.25) -> None:
        """Tell actors whether they may insert: on every change, and as a heartbeat."""
        pub = self.session.declare_publisher(wire.replay_flow_key(self.run_id))
        last, last_sent = None, 0.0
        while not self.stop_event.wait(period_s):
            ok = self.core.insert_allowed()
            now = time.monotonic()
            if ok != last or now - last_sent >= heartbeat_s:
                pub.put(wire.encode_json({"insert_ok": ok}))
                last, last_sent = ok, now

    @property
    def _wal_bounded(self) -> bool:
        return self.wal is not None and self.wal.enabled and self.wal.max_bytes > 0

    def _checkpoint_loop(self, retry_s: float = 5.0) -> None:
        """A checkpoint every ``checkpoint_every_s`` (0: never on a timer), and at once when the
        write-ahead log outgrows ``replay.wal_max_mb`` (a failed one is retried after ``retry_s``
        at the soonest, so a full disk does not make it spin)."""
        every = self.checkpoint_every_s if self.checkpoint_every_s > 0 else None
        while not self.stop_event.is_set():
            self._wake.wait(every)
            if self.stop_event.is_set():
                return
            if self.checkpoint() is None:
                self.stop_event.wait(max(retry_s, every or 0.0))

    def checkpoint(self) -> dict | None:
        """Write a checkpoint now (inserts and samples continue meanwhile)."""
        if self.checkpoint_dir is None:
            return None
        with self._checkpoint_lock:
            try:
                info = write_checkpoint(self.core, self.checkpoint_dir, self.wal)
            except OSError as exc:  # a full disk must not take the server down: report, count, retry later
                self.core.checkpoint_failures += 1
                shutil.rmtree(self.checkpoint_dir.with_name(self.checkpoint_dir.name + ".tmp"), ignore_errors=True)
                print(f"replay-server: checkpoint failed ({exc}); serving on, the previous checkpoint stays valid, "
                      f"retrying in {self.checkpoint_every_s:g} s ({self.core.checkpoint_failures} failed so far)",
                      file=sys.stderr, flush=True)
                return None
        self.core.last_checkpoint = {**info, "monotonic": time.monotonic()}
        return info

    def _control(self, payload: bytes) -> bytes:
        try:
            body = wire.decode_json(payload)
        except wire.WireError as exc:
            return wire.encode_json({"ok": False, "error": str(exc)})
        return wire.encode_json(self.core.handle_control(body))

    def stop(self) -> None:
        self.stop_event.set()
        self._wake.set()

    def join(self, timeout_s: float) -> list[str]:
        """Wait (at most ``timeout_s`` in all) for the service threads to end; the names of those
        still running. Call it after the sessions are closed: that is what wakes a thread blocked
        in a channel's ``recv()``."""
        deadline = time.monotonic() + timeout_s
        for thread in self._threads:
            thread.join(max(0.0, deadline - time.monotonic()))
        return [t.name for t in self._threads if t.is_alive()]


def build_core(cfg: RunConfig, spec: EnvSpec, shard: int = 0) -> ReplayCore:
    """The replay core for a run (or for shard ``shard`` of a sharded replay: its share of the
    capacity, ``ReplayConfig.shard``): schema from the env's spec, demo shards validated against
    it, a place in its book of actors kept for each of the run's env workers."""
    demo = None
    if cfg.replay.demo_paths:  # demos become the same n-step items the actors send
        demo = load_demo_table(cfg.replay.demo_paths, spec, cfg.learner.n_step, cfg.learner.gamma)
    return ReplayCore(cfg.replay.shard(shard), spec.schema, demo, own_actors=worker_names(cfg.actor.workers))


#: Env fields added after replay checkpoints were first written, with their defaults: such a field
#: joins the digest only when a run sets it, so a run started before it existed still resumes
#: (``laneshift train --resume``) on the version that added it. Add every new env field here.
ENV_FIELDS_ADDED_LATER: dict[str, object] = {"alongside_features": False, "gap_features": False, "shield": False,
                                             "shield_gap": SHIELD_GAP, "shield_decel": SHIELD_DECEL,
                                             "frame_supersample": 1, "frame_interval": 1,
                                             "frame_centering": 0.5, "frame_scale": 2.0}


def config_digest(cfg: RunConfig, shard: int = 0) -> str:
    """What a replay checkpoint must match to be restored: the env and the table layout (a
    shard's checkpoint: that shard of that many). (Not the router endpoint or ports: those change
    when a run is resumed.)"""
    import hashlib

    env = cfg.to_dict()["env"]
    for name, default in ENV_FIELDS_ADDED_LATER.items():  # left at its default: the digest of before
        if env.get(name) == default:
            env.pop(name, None)
    key = {"env": env, "capacity": cfg.replay.capacity, "demo_mode": cfg.replay.demo_mode,
           "demo_ratio": cfg.replay.demo_ratio, "n_step": cfg.learner.n_step}
    if cfg.replay.shards > 1:  # a single server's digest stays what it was: its checkpoints restore
        key["shard"] = [shard, cfg.replay.shards]
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]


def shard_files(cfg: RunConfig, shard: int = 0) -> tuple[str, str]:
    """A replay server's checkpoint directory and final-stats file names in the run dir:
    ``replay_checkpoint`` and ``replay_stats.json``, with ``_shard<i>`` when sharded."""
    tag = f"_shard{shard}" if cfg.replay.shards > 1 else ""
    return f"replay_checkpoint{tag}", f"replay_stats{tag}.json"


class ReplayServer:
    """The whole replay server of a run: core, checkpoint restore, zenoh service, HTTP API.

    ``start()`` returns once it serves; ``stop()`` writes the final checkpoint and
    ``replay_stats.json`` and returns the final stats. The ``laneshift replay-server`` process and
    the Ray actor (``deploy.actors``) both run this.
    """

    def __init__(self, cfg: RunConfig, spec: EnvSpec, embedded_router: bool = False, shard: int = 0):
        self.cfg, self.spec, self.embedded_router, self.shard = cfg, spec, embedded_router, shard
        self.namespace = wire.replay_namespace(cfg.transport.run_id, shard, cfg.replay.shards)  # ValueError: named
        self.who = "replay-server" if cfg.replay.shards == 1 else f"replay-server shard {shard}/{cfg.replay.shards}"
        self.http_port: int | None = None
        self.restored = 0
        self._stop = threading.Event()
        self._sessions: list[zenoh.Session] = []

    def start(self) -> dict:
        cfg = self.cfg
        self.core = core = build_core(cfg, self.spec, self.shard)  # ValueError: config or shard mismatch, named
        core.identity = {"run_id": cfg.transport.run_id, "config_digest": config_digest(cfg, self.shard)}
        self.demo_digest = core.demo.digest()
        checkpoint_name, self.stats_name = shard_files(cfg, self.shard)
        self.checkpoint_dir = Path(cfg.train.run_dir) / checkpoint_name
        self._lock_checkpoint_dir()
        self.wal = self._restore(core)  # CheckpointError (WalError): named
        transport.use_service_runtime()
        mode = "router" if self.embedded_router else "client"
        # Sample replies leave on this session: unbatched (transport.session_config says why).
        session = transport.open_session(cfg.transport, mode, cfg.max_message_bytes, who=self.who,
                                         stop=self._stop, batching=False)
        try:
            ingest_session = transport.open_session(cfg.transport, "client", cfg.max_message_bytes,
                                                    who=self.who, stop=self._stop)
        except BaseException:
            transport.close_sessions([session], timeout_s=10.0, who=self.who)
            raise
        self._sessions = [ingest_session, session]
        # Every replay key of this server is built from its namespace: the run id, or <run>/shard-<i>.
        self.service = ReplayService(core, session, self.namespace, self.checkpoint_dir,
                                     cfg.replay.checkpoint_every_s, ingest_session, self.wal).start()
        port = core.cfg.http_port  # this shard's (ReplayConfig.shard: the fixed port + shard index)
        if port >= 0:
            from .http_api import serve_http  # imported only when asked for: fastapi takes a while

            try:
                _, self.http_port = serve_http(core, cfg.replay.http_host, port, self._stop)
            except OSError as exc:
                self.close()
                raise OSError(f"replay.http_port {port}: {exc}") from None
            shown = cfg.replay.http_host
            if shown in ("0.0.0.0", "::"):  # bound everywhere: name an address others can use
                shown = cfg.transport.router.split("/", 1)[1].rsplit(":", 1)[0]
            core.http_url = f"http://{shown}:{self.http_port}"
            print(f"{self.who}: HTTP inspection API on http://{cfg.replay.http_host}:{self.http_port} "
                  f"(/stats, /metrics, /docs)", flush=True)
        stats = core.stats()
        print(f"{self.who}: serving run {cfg.transport.run_id!r} on {cfg.transport.router} "
              f"(mode {core.mode}, online capacity {core.online.capacity}, demo items {core.demo.size}, "
              f"demo sha256 {stats['tables']['demo']['sha256'][:12] or '-'})", flush=True)
        return {"http_port": self.http_port, "restored": self.restored}

    def _restore(self, core: ReplayCore) -> wal_log.WriteAheadLog:
        """The checkpoint (if any, and ``replay.restore``), then the write-ahead log's segments
        after it; returns the log this process appends to (``replay.wal``), attached to the core.
        Without ``replay.restore`` a stale log is deleted: it must never be replayed later."""
        cfg = self.cfg.replay
        wal_dir = wal_log.directory_for(self.checkpoint_dir)
        unfinished = self.checkpoint_dir.with_name(self.checkpoint_dir.name + ".tmp")
        if unfinished.exists():  # the previous process died writing it; the next checkpoint clears it
            print(f"{self.who}: {unfinished} is a checkpoint the previous process died writing: not used (the "
                  f"last whole checkpoint and the write-ahead log after it are)", flush=True)
        has_checkpoint = (self.checkpoint_dir / "meta.json").exists()
        try:
            meta = read_meta(self.checkpoint_dir) if has_checkpoint else {}
        except CheckpointError:
            if cfg.restore:
                raise
            meta = {}  # not restored anyway
        # Generations go on above every one a checkpoint or a segment names (also across restore=false).
        after = max(wal_log.last_generation(wal_dir), int(meta.get("wal_from") or 0))
        if cfg.restore:
            if has_checkpoint:
                self.restored = restore_checkpoint(core, self.checkpoint_dir)
                print(f"{self.who}: restored {self.restored} items from {self.checkpoint_dir}", flush=True)
            done = wal_log.replay(core, wal_dir, meta.get("wal_from"))
            if done["segments"]:
                core.wal_replayed = done
                self.restored += done["items"]
                torn = done["torn"] + done["corrupt"]
                print(f"{self.who}: replayed {done['batches']} batches ({done['items']} items) from the write-ahead "
                      f"log {wal_dir} ({done['segments']} segments, {done['duplicates']} already held"
                      + (f"; {torn} torn record(s), {done['dropped_bytes']} bytes, dropped: their batches count as lost"
                         if torn else "") + ")", flush=True)
        elif wal_log.clear(wal_dir):
            print(f"{self.who}: replay.restore is off: deleted the write-ahead log in {wal_dir}", flush=True)
        log = wal_log.WriteAheadLog(wal_dir, cfg.wal, core.identity, int(cfg.wal_max_mb * 2**20), after + 1,
                                    kept={g: p.stat().st_size for g, p in wal_log.segments(wal_dir)})
        core.wal = log
        return log

    def _lock_checkpoint_dir(self) -> None:
        """One live replay server per run dir: a second would restore, then overwrite, the first
        one's checkpoint. The lock goes with the process (kill -9 included), so a restart gets it."""
        import fcntl

        path = self.checkpoint_dir.with_name(self.checkpoint_dir.name + ".lock")
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ValueError(f"another replay server is using {self.checkpoint_dir.parent} (its run dir): give "
                             f"this one its own train.run_dir") from None
        self._lock_fd = fd

    def stop(self) -> dict:
        """Final checkpoint (SIGTERM/SIGINT keep everything received), stats file, sessions closed."""
        self._stop.set()
        self.service.stop()
        self.service.drain(timeout_s=10.0)  # what was logged goes into the table before the final checkpoint
        final_ckpt = self.service.checkpoint()
        if final_ckpt:
            print(f"{self.who}: final checkpoint of {final_ckpt['items']} items in {final_ckpt['seconds']} s",
                  flush=True)
        self.close()
        # No thread of ours may still be inside a zenoh call when the interpreter finalizes (see
        # tools/cli_services.py, end_service_process); the sessions are closed, so their channels have woken them.
        left = self.service.join(timeout_s=10.0)
        if left:
            print(f"{self.who}: threads still running after the sessions closed: {', '.join(left)}",
                  file=sys.stderr, flush=True)
        else:  # nothing appends any more: the last segment closed (deleted if the final checkpoint holds it all)
            self.wal.close()
        final = self.core.stats(all_actors=True)  # a file, not a reply: every actor
        final["demo_digest_start"], final["demo_digest_end"] = self.demo_digest, self.core.demo.digest()
        out = Path(self.cfg.train.run_dir) / self.stats_name
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(final, indent=2))
        except OSError as exc:
            print(f"{self.who}: could not write {out}: {exc}", file=sys.stderr, flush=True)
        print(f"{self.who}: stopped; stored {final['tables']['online']['inserted']} items, "
              f"rejected {sum(final['rejected'].values())}", flush=True)
        return final

    def request_stop(self) -> None:
        """From a signal handler: ends a wait for the router (``open_session``'s stop) and the HTTP API."""
        self._stop.set()

    def close(self) -> None:
        self._stop.set()
        if getattr(self, "_lock_fd", None) is not None:
            os.close(self._lock_fd)
            self._lock_fd = None
        sessions, self._sessions = self._sessions, []
        transport.close_sessions(sessions, timeout_s=10.0, who=self.who)


def run_replay_server(cfg: RunConfig, spec: EnvSpec, *, embedded_router: bool = False,
                      ready_file: str | None = None, shard: int = 0) -> int:
    """Serve until SIGINT/SIGTERM. Writes ``ready_file`` (JSON) once it is serving."""
    stop = threading.Event()
    try:
        server = ReplayServer(cfg, spec, embedded_router, shard)
    except ValueError as exc:  # a shard index out of range
        print(f"replay-server: {exc}", file=sys.stderr)
        return 2

    def on_signal(*_: object) -> None:
        stop.set()
        server.request_stop()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    try:
        info = server.start()
    except InterruptedError as exc:  # SIGINT/SIGTERM before any router answered: nothing was served
        print(f"replay-server: {exc}", flush=True)
        server.close()
        return 0
    except CheckpointError as exc:
        print(f"replay-server: {exc}; remove it or start with replay.restore=false", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:  # config or shard mismatch, or the HTTP port: refuse, naming it
        print(f"replay-server: {exc}", file=sys.stderr)
        return 2
    if ready_file:
        Path(ready_file).write_text(json.dumps({"pid": os.getpid(), "time": time.time(), "http_port": info["http_port"]}))
    while not stop.wait(0.5):
        pass
    server.stop()
    return 0
