"""`laneshift bench replay`: replay-server ingest and sample speed over zenoh on loopback.

What runs is the topology `laneshift train --local` gives users: a `laneshift router` process and
a `laneshift replay-server` process as its client (straight scenario, vector or grayscale
observations, ``replay.samples_per_insert 0`` so the rate limiter never throttles, ``min_size 1``).
Synthetic actors are separate OS processes (this module's ``_publish`` entry point), each a zenoh
client publishing pre-encoded TRANSITIONS messages (``wire.encode_transitions``, valid per-actor
``seq``) with ``CongestionControl.BLOCK`` as fast as it can, several actor keys per process.

Measured:

- ingest transitions/s = what the server *stored* over a window after a warm-up
  (``replay/stats``: ``tables.online.inserted`` against the server's own ``uptime_s``), not what
  publishers claim to have sent; lost (per-actor ``seq`` gaps), rejected and never-stored items
  are reported next to it;
- sample latency: ``replay/sample`` queries with ``SampleRequest(256)`` from this process, timed
  from the query to the decoded batch (``wire.decode_batch``), on an idle server and while two
  actors insert;
- bytes per stored transition: the online table's ``bytes`` / ``capacity``;
- ingest with 2 .. 64 actors (fixed number of publisher processes, actor keys multiplexed);
- CPU used by each process over every window (from /proc), so a slow number can be attributed.

    laneshift bench replay                      # text
    laneshift bench replay --duration 5 --json  # one JSON object
    laneshift bench replay --set replay.wal=off --work-dir /data/bench   # the server without its write-ahead log

The replay servers run with the config's defaults (the write-ahead log on: ``replay.wal``) except
what the bench sets (no periodic checkpoint, no restore) and ``--set`` (applied last); their run
dirs (the log's segments) go under ``--work-dir``, so put it on the disk the runs use.

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import signal
import socket
import struct
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, TextIO

import numpy as np

from laneshift import transport, wire
from laneshift.argtypes import parse_set
from laneshift.config import ConfigError, ReplayConfig, TransportConfig, load_run_config
from laneshift.progress import progress
from laneshift.progress import write as progress_write

TARGET_INGEST_VECTOR_PER_S = 200_000
TARGET_SAMPLE_P99_MS = 5.0
SAMPLE_BATCH = 256
FILL_TIMEOUT_S = 300
DRAIN_S = 0.1  # publisher: pause between its last put and closing the session (none lost without it, measured)
# Placeholders written by wire.encode_transitions, then overwritten in place with the real values
# padded by spaces to the same width (JSON allows whitespace after a number), so each message costs
# one join instead of a full encode. 16 digits, below the wire's 2**53 bound for header integers.
_SEQ_MARK = 1_111_111_111_111_111
_STEPS_MARK = 2_222_222_222_222_222
_MARK_WIDTH = 16


class BenchError(RuntimeError):
    pass


# ----------------------------------------------------------------------------- CLI


def register(subparsers: Any) -> None:
    """Add the ``replay`` sub-command (``laneshift.cli`` calls this under ``laneshift bench``)."""
    p = subparsers.add_parser("replay", help="replay server ingest rate, sample latency, memory per transition")
    _add_arguments(p)
    p.set_defaults(func=run)


def _actor_list(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--actors takes a comma-separated list of integers, got {text!r}") from None
    if not values or any(v < 1 or v > 1024 for v in values):
        raise argparse.ArgumentTypeError(f"--actors values must be 1..1024, got {text!r}")
    return values


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=3.0, help="seconds per measurement window (default 3)")
    p.add_argument("--batch", type=int, default=32,
                   help="transitions per message, like actor.send_every (default 32)")
    p.add_argument("--actors", type=_actor_list, default=[2, 8, 32, 64],
                   help="actor counts of the scaling table (default 2,8,32,64)")
    p.add_argument("--publishers", type=int, default=2,
                   help="publisher processes the actors are spread over (default 2)")
    p.add_argument("--warmup", type=float, default=0.5, help="seconds of publishing before a window opens")
    p.add_argument("--paced-rate", type=float, default=20_000,
                   help="transitions/s of the paced-ingest sample-latency run (default 20000, about 15x what "
                        "2 training workers produce; 0 skips it)")
    p.add_argument("--capacity-vector", type=int, default=1_000_000, help="online capacity, vector run")
    p.add_argument("--capacity-grayscale", type=int, default=20_000, help="online capacity, grayscale run")
    p.add_argument("--no-grayscale", dest="grayscale", action="store_false",
                   help="vector runs only (at --batch 1024 a grayscale message is 80 MB)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="a config field for the replay servers, applied after the bench's own, e.g. "
                        "--set replay.wal=off (repeatable)")
    p.add_argument("--work-dir", default=None,
                   help="where the servers' run dirs (and write-ahead logs) go (default: a new temp dir, removed after)")


def run(args: argparse.Namespace) -> int:
    if args.duration <= 0 or args.warmup < 0:
        raise SystemExit("--duration must be > 0 and --warmup >= 0")
    if not 1 <= args.batch <= wire.MAX_BATCH_ROWS or args.publishers < 1:
        raise SystemExit(f"--batch must be 1..{wire.MAX_BATCH_ROWS} and --publishers >= 1")
    if min(args.capacity_vector, args.capacity_grayscale) < SAMPLE_BATCH:
        raise SystemExit(f"capacities must be >= {SAMPLE_BATCH}")
    try:
        load_run_config(overrides=parse_set(args.set))  # a bad --set: refused here, not in a child
    except ConfigError as exc:
        raise SystemExit(f"bench replay: {exc}") from None
    log = sys.stderr if args.json else sys.stdout
    try:
        result = bench(args, log=log)
    except BenchError as exc:
        print(f"bench replay: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result))
    else:
        print(format_result(result))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="laneshift bench replay", description=__doc__.splitlines()[0])
    _add_arguments(parser)
    return run(parser.parse_args(argv))


# ----------------------------------------------------------------------------- synthetic publisher


class _Patcher:
    """A pre-encoded TRANSITIONS message whose ``seq`` and ``env_steps`` can be rewritten cheaply."""

    def __init__(self, message: bytes):
        (hlen,) = struct.unpack_from("<I", message, 8)
        end = 12 + hlen
        marks = []
        for field, mark in (("seq", _SEQ_MARK), ("env_steps", _STEPS_MARK)):
            needle = f'"{field}":{mark}'.encode()
            pos = message.find(needle, 0, end)
            if pos < 0 or message.find(needle, pos + 1, end) >= 0:
                raise BenchError(f"placeholder for {field} not found exactly once in the header")
            marks.append((pos + len(needle) - _MARK_WIDTH, field))
        marks.sort()
        self.order = [f for _, f in marks]
        (a, _), (b, _) = marks
        self.pieces = (message[:a], message[a + _MARK_WIDTH:b], message[b + _MARK_WIDTH:])

    def build(self, seq: int, env_steps: int) -> bytes:
        vals = {"seq": seq, "env_steps": env_steps}
        p0, p1, p2 = self.pieces
        return b"".join((p0, b"%-16d" % vals[self.order[0]], p1, b"%-16d" % vals[self.order[1]], p2))


MESSAGES_PER_ACTOR = 4


def synthetic_message(actor: str, schema: wire.TransitionSchema, rows: int, rng: np.random.Generator) -> _Patcher:
    """Random but valid transitions for ``schema``, encoded once with placeholder counters."""
    shape = (rows, *schema.obs_shape)
    dtype = np.dtype(schema.obs_dtype)
    if dtype.kind == "f":
        obs = rng.standard_normal(shape).astype(dtype)
        next_obs = rng.standard_normal(shape).astype(dtype)
    elif len(schema.obs_shape) == 3:  # a frame-stacking env's stream: each item one new frame
        stack = schema.obs_shape[0]
        frames = rng.integers(0, 256, size=(rows + stack, *schema.obs_shape[1:]), dtype=np.uint8).astype(dtype)
        obs = np.stack([frames[i:i + stack] for i in range(rows)])
        next_obs = np.stack([frames[i + 1:i + 1 + stack] for i in range(rows)])
    else:
        obs = rng.integers(0, 256, size=shape, dtype=np.uint8).astype(dtype)
        next_obs = rng.integers(0, 256, size=shape, dtype=np.uint8).astype(dtype)
    batch = wire.TransitionBatch.from_arrays(
        actor=actor, seq=_SEQ_MARK, weights_version=0, phase=0, env_steps=_STEPS_MARK, obs=obs,
        action=rng.integers(0, schema.n_actions, size=rows), reward=rng.standard_normal(rows).astype(np.float32),
        next_obs=next_obs, terminated=(rng.random(rows) < 0.02).astype(np.uint8), truncated=np.zeros(rows, np.uint8))
    patcher = _Patcher(wire.encode_transitions(batch))
    check = wire.decode_transitions(patcher.build(7, 7 * rows), schema)  # the patched form is a valid message
    if check.seq != 7 or check.env_steps != 7 * rows or check.actor != actor:
        raise BenchError("patched message does not decode to the values written")
    return patcher


def _publisher_main(argv: list[str]) -> int:
    """One synthetic-actor process: publishes for every actor key given, round robin, until SIGTERM."""
    p = argparse.ArgumentParser(prog="python -m laneshift.bench.replay _publish")
    p.add_argument("--router", required=True)
    p.add_argument("--run-id", required=True)
    p.add_argument("--actors", required=True, help="comma-separated actor names")
    p.add_argument("--batch", type=int, required=True)
    p.add_argument("--obs-shape", required=True, help="e.g. 67 or 4,100,100")
    p.add_argument("--obs-dtype", required=True)
    p.add_argument("--n-actions", type=int, required=True)
    p.add_argument("--ready", required=True)
    p.add_argument("--go", required=True, help="publishing starts once this file exists")
    p.add_argument("--report", required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rate", type=float, default=0.0, help="transitions/s for this process (0 = as fast as possible)")
    a = p.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    schema = wire.TransitionSchema(tuple(int(d) for d in a.obs_shape.split(",")), a.obs_dtype, a.n_actions)
    actors = a.actors.split(",")
    rng = np.random.default_rng(a.seed)
    # A few distinct messages per actor, sent in turn: a frame table (replay_server/frames.py) then
    # finds each message's frames new, as with a real env, not remembered from the last send.
    patchers = [[synthetic_message(actor, schema, a.batch, rng) for _ in range(MESSAGES_PER_ACTOR)]
                for actor in actors]
    sent = [0] * len(actors)
    rows = a.batch
    with transport.open_session(TransportConfig(router=a.router, run_id=a.run_id)) as session:
        pubs = [transport.data_publisher(session, wire.transitions_key(a.run_id, actor)) for actor in actors]
        # Until the server's subscription is known (a put before that goes nowhere), or we are stopped.
        matched = transport.wait_for(lambda: stop.is_set() or all(p.matching_status.matching for p in pubs), 60,
                                     interval_s=0.01)
        if not matched or stop.is_set():
            print("publisher: no matching subscriber", file=sys.stderr, flush=True)
            return 3
        Path(a.ready).write_text("ready")
        # Start barrier: wait until the bench says go, so no publisher that started faster than the
        # others sends before the window's opening stats are taken (on a cold machine one publisher
        # filled a small table alone before the second one was ready: an empty window).
        parent = os.getppid()
        go, deadline = Path(a.go), time.monotonic() + 120
        while not go.exists():
            if stop.is_set() or os.getppid() != parent or time.monotonic() > deadline:
                return 0 if stop.is_set() else 3
            time.sleep(0.005)
        t0 = time.monotonic()
        total = 0
        while not stop.is_set():
            if os.getppid() != parent:  # the bench died without stopping us
                break
            for k in range(len(pubs)):
                s = sent[k]
                pubs[k].put(patchers[k][s % MESSAGES_PER_ACTOR].build(s, (s + 1) * rows))
                sent[k] = s + 1
                total += rows
                if a.rate > 0:  # paced: sleep until this message's slot
                    ahead = t0 + total / a.rate - time.monotonic()
                    if ahead > 0:
                        stop.wait(ahead)
        elapsed = time.monotonic() - t0
        report = {"actors": {actor: {"batches": n, "items": n * rows} for actor, n in zip(actors, sent)},
                  "elapsed_s": elapsed}
        Path(a.report).write_text(json.dumps(report))
        time.sleep(DRAIN_S)  # let zenoh's transmit queue drain before the session closes
    return 0


# ----------------------------------------------------------------------------- CPU accounting


_CLK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _proc_cpu_s(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / _CLK  # utime + stime
    except (OSError, IndexError, ValueError):
        return None


def _machine_busy_s() -> float | None:
    try:
        with open("/proc/stat") as f:
            vals = [int(v) for v in f.readline().split()[1:]]
        return (sum(vals[:8]) - vals[3] - vals[4]) / _CLK  # everything but idle and iowait
    except (OSError, IndexError, ValueError):
        return None


class _CpuMeter:
    """Cores used per role (server, router, publishers, bench) and by the whole machine."""

    def __init__(self, roles: dict[str, list[int]]):
        self.roles = {**roles, "bench": [os.getpid()]}
        self.t0 = time.monotonic()
        self.start = self._snap()

    def _snap(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for role, pids in self.roles.items():
            vals = [_proc_cpu_s(pid) for pid in pids]
            out[role] = None if any(v is None for v in vals) else sum(vals)  # type: ignore[arg-type]
        out["machine"] = _machine_busy_s()
        return out

    def cores(self) -> dict[str, float | None]:
        end, wall = self._snap(), time.monotonic() - self.t0
        res = {k: (None if end[k] is None or self.start[k] is None else round((end[k] - self.start[k]) / wall, 2))
               for k in end}
        ours = [res[k] for k in self.roles]
        if res["machine"] is not None and all(v is not None for v in ours):
            res["other"] = round(max(0.0, res["machine"] - sum(ours)), 2)  # type: ignore[operator]
        return res


# ----------------------------------------------------------------------------- the benchmark


def wait_for_router(endpoint: str, check_alive: Callable[[], None], timeout_s: float = 60.0) -> None:
    """A zenoh client retries forever: make sure the router listens before opening a session."""
    host, port = endpoint.split("/", 1)[1].rsplit(":", 1)
    deadline = time.monotonic() + timeout_s
    while True:
        check_alive()
        try:
            socket.create_connection((host, int(port)), timeout=1).close()
            return
        except OSError:
            if time.monotonic() > deadline:
                raise BenchError(f"the router did not listen on {endpoint} within {timeout_s:g} s") from None
            time.sleep(0.05)


class _Bench:
    def __init__(self, args: argparse.Namespace, work: Path, log: TextIO):
        from laneshift.deploy.processes import ProcessGroup

        self.args = args
        self.work = work
        self.overrides = parse_set(getattr(args, "set", None) or [])  # --set, for the replay servers
        self.log = log
        self.endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
        self.group = ProcessGroup(work / "logs")
        self.py = [sys.executable, "-m", "laneshift"]
        self.session = None
        self.n_pub = 0
        self.t0 = time.monotonic()
        self.live: set[str] = set()  # children that must be running now (stopped ones are removed)
        self.bar = progress(total=0, desc="bench replay", unit="phase", disable=True)  # bench() sets the real one

    def say(self, msg: str) -> None:
        progress_write(f"[bench replay {time.monotonic() - self.t0:5.1f}s] {msg}", file=self.log)

    # --- processes

    def start_router(self) -> None:
        self.group.start("router", [*self.py, "router", "--listen", self.endpoint])
        self.live.add("router")
        wait_for_router(self.endpoint, self.check_alive)

    def start_server(self, name: str, observation: str, capacity: int) -> wire.TransitionSchema:
        from laneshift.config import save_run_config
        from laneshift.deploy.processes import ChildFailed, wait_for_file
        from laneshift.actors.envs import spec_of

        overrides: dict[str, Any] = {
            "env.scenario": "straight", "env.observation": observation, "replay.capacity": capacity,
            "replay.samples_per_insert": 0, "replay.min_size": 1, "transport.router": self.endpoint,
            "transport.run_id": name, "train.run_dir": str(self.work / name)}
        fields = {f.name for f in dataclasses.fields(ReplayConfig)}
        if "checkpoint_every_s" in fields:
            overrides["replay.checkpoint_every_s"] = 0  # no periodic table checkpoint inside a window
        if "restore" in fields:
            overrides["replay.restore"] = False
        overrides.update(self.overrides)
        cfg = load_run_config(overrides=overrides)
        path = save_run_config(cfg, self.work / f"{name}.yaml")
        ready = self.work / f"{name}.ready"
        self.group.start(name, [*self.py, "replay-server", "--config", str(path), "--ready-file", str(ready)])
        self.live.add(name)
        try:
            wait_for_file(ready, 120, self.group, name)
        except ChildFailed as exc:
            raise BenchError(str(exc)) from None
        return spec_of(cfg.env).schema

    def start_and_fill(self, result: dict, name: str, observation: str, capacity: int,
                       label: str) -> wire.TransitionSchema:
        """A replay server for ``observation``, its table filled once by 2 actors (fresh memory
        pages, so the timed runs after it do not pay for them); ``<observation>_obs`` and
        ``fill_<observation>`` go into ``result``."""
        self.say(f"{observation}: starting replay server (capacity {capacity:,})")
        schema = self.start_server(name, observation, capacity)
        result[f"{observation}_obs"] = {"shape": list(schema.obs_shape), "dtype": schema.obs_dtype}
        self.say(f"{observation}: first fill of the table with 2 actors (fresh memory pages)")
        result[f"fill_{observation}"] = self.ingest(name, schema, label, 2, fill_to=capacity)
        self.bar.update()
        return schema

    def stop_server(self, name: str) -> None:
        """SIGKILL: the table is throwaway, and a clean stop would write it to disk as a final
        checkpoint (up to 1.6 GB for the grayscale table)."""
        self.live.discard(name)
        proc = self.group.procs[name]
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)

    def stats(self, run_id: str) -> dict:
        data = transport.query(self.session, wire.replay_stats_key(run_id), b"", 10.0)
        if data is None:
            self.check_alive()
            raise BenchError(f"replay server {run_id} did not answer a stats query in 10 s")
        return wire.decode_json(data)

    def check_alive(self) -> None:
        from laneshift.deploy.processes import ChildFailed

        try:
            self.group.check_alive(sorted(self.live))
        except ChildFailed as exc:
            raise BenchError(str(exc)) from None

    def start_publishers(self, run_id: str, schema: wire.TransitionSchema, names: list[str],
                         rate: float = 0.0) -> list[dict]:
        from laneshift.deploy.processes import ChildFailed, wait_for_file

        count = min(len(names), self.args.publishers)
        pubs = []
        for j in range(count):
            self.n_pub += 1
            tag = f"pub{self.n_pub}"
            ready, report, go = self.work / f"{tag}.ready", self.work / f"{tag}.json", self.work / f"{tag}.go"
            argv = [sys.executable, "-m", "laneshift.bench.replay", "_publish", "--router", self.endpoint,
                    "--run-id", run_id, "--actors", ",".join(names[j::count]), "--batch", str(self.args.batch),
                    "--obs-shape", ",".join(map(str, schema.obs_shape)), "--obs-dtype", schema.obs_dtype,
                    "--n-actions", str(schema.n_actions), "--ready", str(ready), "--go", str(go), "--report", str(report),
                    "--seed", str(self.n_pub), "--rate", str(rate / count)]
            proc = self.group.start(tag, argv)
            self.live.add(tag)
            pubs.append({"name": tag, "proc": proc, "ready": ready, "go": go, "report": report})
        try:
            for pub in pubs:
                wait_for_file(pub["ready"], 60, self.group, pub["name"])
        except ChildFailed as exc:
            self.stop_publishers(pubs)
            raise BenchError(str(exc)) from None
        return pubs

    @staticmethod
    def go(pubs: list[dict]) -> None:
        """Release the start barrier of every publisher in ``pubs``."""
        for pub in pubs:
            pub["go"].write_text("go")

    def stop_publishers(self, pubs: list[dict]) -> dict[str, dict]:
        for pub in pubs:
            self.live.discard(pub["name"])
            if pub["proc"].poll() is None:
                pub["proc"].send_signal(signal.SIGTERM)
        sent: dict[str, dict] = {}
        for pub in pubs:
            self.group.stop(pub["name"], grace_s=20)
            try:
                sent.update(json.loads(pub["report"].read_text())["actors"])
            except (OSError, ValueError, KeyError):
                # Its actors count as "unknown sent" (never_stored: None); say why in the bench log.
                rc = pub["proc"].poll()
                self.say(f"publisher {pub['name']} left no report (exit {rc}); end of its log:\n"
                         f"{self.group.log_tail(pub['name'])}")
        return sent

    def actors(self, run_id: str) -> dict[str, dict]:
        """Every actor's counters, paged through ``{"cmd": "actors"}`` (a stats reply lists only
        the first 32 by name: after the scaling rows, this window's actors are not among them)."""
        out: dict[str, dict] = {}
        while True:
            data = transport.query(self.session, wire.replay_control_key(run_id),
                                   wire.encode_json({"cmd": "actors", "offset": len(out), "limit": 256}), 10.0)
            if data is None:
                self.check_alive()
                raise BenchError(f"replay server {run_id} did not answer an actors query in 10 s")
            page = wire.decode_json(data)
            out.update(page["actors"])
            if not page["actors"] or len(out) >= page["total"]:
                return out

    def settle(self, run_id: str, sent: dict[str, dict], timeout_s: float = 60.0) -> tuple[dict, dict[str, dict]]:
        """Wait until the server stored everything sent (or stopped storing); returns the stats
        and every actor's counters."""
        deadline = time.monotonic() + timeout_s
        last, stable_since = -1, time.monotonic()
        while True:
            st = self.stats(run_id)
            actors = self.actors(run_id)
            got = {a: actors.get(a, {}).get("items", 0) for a in sent}
            if all(got[a] >= sent[a]["items"] for a in sent):
                return st, actors
            now = time.monotonic()
            if st["tables"]["online"]["inserted"] != last:
                last, stable_since = st["tables"]["online"]["inserted"], now
            elif now - stable_since > 3.0 or now > deadline:
                return st, actors
            time.sleep(0.1)

    # --- measurements

    def ingest(self, run_id: str, schema: wire.TransitionSchema, label: str, n_actors: int,
               sample_during: bool = False, fill_to: int | None = None, rate: float = 0.0) -> dict:
        """Ingest rate with ``n_actors`` synthetic actors over one window.

        ``sample_during``: time sample queries during the window. ``rate``: publishers paced to this
        many transitions/s in all (0 = as fast as they can). ``fill_to``: no warm-up; the
        window runs until the table has taken ``fill_to`` items in all (the first fill of the ring,
        when every write lands on a page never touched before).
        """
        a = self.args
        names = [f"{label}a{i}" for i in range(n_actors)]
        before = self.stats(run_id)
        pubs = self.start_publishers(run_id, schema, names, rate)
        latency = None
        try:
            if fill_to is None:  # steady state: the window opens after a warm-up
                self.go(pubs)
                time.sleep(a.warmup)
            self.check_alive()
            meter = _CpuMeter({"server": [self.group.procs[run_id].pid], "router": [self.group.procs["router"].pid],
                               "publishers": [p["proc"].pid for p in pubs]})
            s0 = self.stats(run_id)
            if fill_to is not None:  # first fill: the window opens before the first transition is sent
                self.go(pubs)
            if sample_during:
                latency = self.sample_latency(run_id, schema, a.duration, warmup_n=3, min_n=5)
            elif fill_to is not None:
                deadline = time.monotonic() + FILL_TIMEOUT_S
                start = s0["tables"]["online"]["inserted"]
                with progress(total=fill_to, desc=f"fill {run_id}", unit="transition", unit_scale=True,
                              leave=False) as fill:
                    while (inserted := self.stats(run_id)["tables"]["online"]["inserted"]) < fill_to:
                        if time.monotonic() > deadline:
                            raise BenchError(f"the table did not take {fill_to:,} items in {FILL_TIMEOUT_S} s")
                        fill.update(max(0, min(inserted - start, fill_to) - fill.n))
                        self.check_alive()
                        time.sleep(0.05)
                    fill.update(max(0, fill_to - fill.n))
            else:
                time.sleep(a.duration)
            s1 = self.stats(run_id)
            cores = meter.cores()
            self.check_alive()
        finally:
            sent = self.stop_publishers(pubs)
        after, actors_after = self.settle(run_id, sent)
        window = s1["uptime_s"] - s0["uptime_s"]
        stored = s1["tables"]["online"]["inserted"] - s0["tables"]["online"]["inserted"]
        rate = stored / window if window > 0 else 0.0
        lost = sum(actors_after.get(n, {}).get("lost_batches", 0) for n in names)
        received = sum(actors_after.get(n, {}).get("items", 0) for n in names)
        total_sent = sum(s["items"] for s in sent.values()) if len(sent) == len(names) else None
        rejected = sum(after["rejected"].values()) - sum(before["rejected"].values())
        server_cores = cores.get("server")
        row = {"actors": n_actors, "publisher_processes": len(pubs), "ingest_per_s": round(rate, 1),
               "us_per_transition": round(1e6 / rate, 3) if rate else None,
               # CPU the server process spent per stored transition: unlike the rate, not skewed by
               # other load on the machine taking cores away from the server.
               "server_cpu_us_per_transition": round(server_cores * 1e6 / rate, 3) if rate and server_cores else None,
               "messages_per_s": round(rate / a.batch, 1), "window_s": round(window, 3), "stored_in_window": stored,
               "sent": total_sent, "stored": received,
               "never_stored": None if total_sent is None else total_sent - received,
               "lost_batches": lost, "rejected": rejected, "cores": cores}
        if latency is not None:
            row["sample"] = latency
        return row

    def sample_latency(self, run_id: str, schema: wire.TransitionSchema, duration: float,
                       warmup_n: int = 20, min_n: int = 20) -> dict:
        req = wire.encode_sample_request(wire.SampleRequest(SAMPLE_BATCH))
        key = wire.sample_key(run_id)

        def once() -> float:
            t = time.perf_counter()
            data = transport.query(self.session, key, req, 10.0)
            if data is None:
                self.check_alive()
                raise BenchError("no reply to a sample query in 10 s")
            if wire.peek_kind(data) == wire.Kind.ERROR:
                raise BenchError(f"sample query refused: {wire.decode_error(data)}")
            batch = wire.decode_batch(data, schema)
            dt = time.perf_counter() - t
            if batch.action.shape[0] != SAMPLE_BATCH:
                raise BenchError(f"sample returned {batch.action.shape[0]} rows, asked {SAMPLE_BATCH}")
            return dt

        timed = time_calls(once, duration, warmup_n, min_n)
        reply = transport.query(self.session, key, req, 10.0) or b""
        return {**timed, "reply_bytes": len(reply)}


def time_calls(once: Callable[[], float], duration: float, warmup_n: int, min_n: int) -> dict:
    """``once()`` (which returns its own seconds) ``warmup_n`` times untimed, then for ``duration``
    seconds and at least ``min_n`` times: count, p50, p99, mean and max in ms."""
    for _ in range(warmup_n):
        once()
    times: list[float] = []
    end = time.perf_counter() + duration
    while time.perf_counter() < end or len(times) < min_n:
        times.append(once())
    ms = np.array(times) * 1e3
    return {"n": len(times), "p50_ms": round(float(np.percentile(ms, 50)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3), "mean_ms": round(float(ms.mean()), 3),
            "max_ms": round(float(ms.max()), 3)}


def _zenoh_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("eclipse-zenoh")
    except PackageNotFoundError:
        return "?"


def bench(args: argparse.Namespace, log: TextIO = sys.stderr) -> dict:
    """Run every measurement; returns the result dict (see ``format_result``)."""
    base = getattr(args, "work_dir", None)
    if base:
        Path(base).mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="lsbench-replay-", dir=base))
    b = _Bench(args, work, log)
    ok = False
    started = time.monotonic()

    def on_term(*_: Any) -> None:
        raise BenchError("terminated")  # unwinds through the finally below: every child is stopped

    in_main = threading.current_thread() is threading.main_thread()
    old_term = signal.signal(signal.SIGTERM, on_term) if in_main else None
    scaling = [2] + [n for n in args.actors if n != 2]
    # Phases: vector fill, one window per actor count, idle sampling, sampling under saturating
    # (and paced) ingest, grayscale fill and ingest.
    phases = 1 + len(scaling) + 2 + (args.paced_rate > 0) + 2 * getattr(args, "grayscale", True)
    b.bar = progress(total=phases, desc="bench replay", unit="phase")
    try:
        b.start_router()
        b.session = transport.open_session(TransportConfig(router=b.endpoint), batching=False)  # as the learner
        result: dict[str, Any] = {
            "config": {"duration_s": args.duration, "warmup_s": args.warmup, "batch": args.batch,
                       "publisher_processes": args.publishers, "sample_batch": SAMPLE_BATCH,
                       "capacity_vector": args.capacity_vector, "capacity_grayscale": args.capacity_grayscale,
                       "paced_rate": args.paced_rate, "replay_set": b.overrides, "work_dir": str(work.parent),
                       "topology": "router process + replay-server client process + publisher client processes",
                       "zenoh": _zenoh_version(), "cpus": os.cpu_count()},
            "targets": {"ingest_vector_per_s": TARGET_INGEST_VECTOR_PER_S, "sample_p99_ms": TARGET_SAMPLE_P99_MS},
        }

        # Vector observations: headline ingest (2 actors), actor scaling, sample latency.
        vec = b.start_and_fill(result, "benchvec", "vector", args.capacity_vector, "vf")
        rows: dict[int, dict] = {}
        for n in scaling:
            b.say(f"vector: ingest with {n} actors for {args.duration:g} s")
            rows[n] = b.ingest("benchvec", vec, f"v{n}", n)
            b.say(f"  {rows[n]['ingest_per_s']:,.0f} transitions/s, cores {rows[n]['cores']}")
            b.bar.update()
        head = rows[2]
        result["ingest_vector_per_s"] = head["ingest_per_s"]
        result["ingest_vector"] = head
        result["actor_scaling"] = [rows[n] for n in args.actors]
        b.say(f"vector: sample latency, batch {SAMPLE_BATCH}, idle server, {args.duration:g} s")
        idle = b.sample_latency("benchvec", vec, args.duration)
        b.bar.update()
        result["sample_p50_ms"], result["sample_p99_ms"] = idle["p50_ms"], idle["p99_ms"]
        result["sample_idle"] = idle
        b.say(f"vector: sample latency while 2 actors insert as fast as they can, {args.duration:g} s")
        loaded = b.ingest("benchvec", vec, "vs", 2, sample_during=True)
        result["sample_under_saturating_ingest"] = {**loaded.pop("sample"), "ingest_meanwhile": loaded}
        b.bar.update()
        if args.paced_rate > 0:
            b.say(f"vector: sample latency while 2 actors insert {args.paced_rate:,.0f} transitions/s, "
                  f"{args.duration:g} s")
            paced = b.ingest("benchvec", vec, "vp", 2, sample_during=True, rate=args.paced_rate)
            result["sample_under_paced_ingest"] = {**paced.pop("sample"), "offered_per_s": args.paced_rate,
                                                   "ingest_meanwhile": paced}
            b.bar.update()
        st = b.stats("benchvec")
        online = st["tables"]["online"]
        result["bytes_per_transition_vector"] = online["bytes"] / online["capacity"]
        result["server_vector_end"] = {"inserted": online["inserted"], "rejected": st["rejected"],
                                       "lost_batches": st["actors_total"]["lost_batches"],
                                       "sampler": st.get("sampler", {}).get("kind", "uniform")}
        b.stop_server("benchvec")  # frees its memory before the grayscale table

        if getattr(args, "grayscale", True):  # grayscale observations: ingest with 2 actors
            gray = b.start_and_fill(result, "benchgray", "grayscale", args.capacity_grayscale, "gf")
            b.say(f"grayscale: ingest with 2 actors for {args.duration:g} s")
            g = b.ingest("benchgray", gray, "g2", 2)
            b.bar.update()
            result["ingest_grayscale_per_s"] = g["ingest_per_s"]
            result["ingest_grayscale"] = g
            online = b.stats("benchgray")["tables"]["online"]
            result["bytes_per_transition_grayscale"] = online["bytes"] / online["capacity"]
            result["grayscale_frames"] = online.get("frames")  # frames held per item (replay_server/frames.py)
            b.stop_server("benchgray")

        result["met"] = {"ingest_vector": result["ingest_vector_per_s"] >= TARGET_INGEST_VECTOR_PER_S,
                         "sample_p99": result["sample_p99_ms"] <= TARGET_SAMPLE_P99_MS}
        result["wall_s"] = round(time.monotonic() - started, 1)
        ok = True
        return result
    finally:
        b.bar.close()
        if b.session is not None:
            b.session.close()
        for name in ("benchvec", "benchgray"):
            if name in b.group.procs:
                b.stop_server(name)
        b.group.stop_all(grace_s=20)
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        if ok:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"[bench replay] failed; logs kept in {work / 'logs'}", file=log, flush=True)


def _cores(c: dict) -> str:
    f = lambda k: "-" if c.get(k) is None else f"{c[k]:.2f}"  # noqa: E731
    return f"{f('server')}/{f('router')}/{f('publishers')}/{f('other')}"


def _loaded_lines(r: dict) -> list[str]:
    out = []
    for key, what in (("sample_under_paced_ingest", "2 actors paced to {:,.0f}/s"),
                      ("sample_under_saturating_ingest", "2 actors flat out")):
        x = r.get(key)
        if x is None:
            continue
        label = what.format(x.get("offered_per_s", 0)) + ":"
        out.append(f"  {label:33s} p50 {x['p50_ms']:.2f} ms  p99 {x['p99_ms']:.2f} ms  max {x['max_ms']:.1f} ms  "
                   f"(n={x['n']}; stored meanwhile {x['ingest_meanwhile']['ingest_per_s']:,.0f} /s)")
    return out


def format_result(r: dict) -> str:
    if "ingest_grayscale" not in r:  # --no-grayscale: the same lines, grayscale figures as 0
        zero = {"ingest_per_s": 0.0, "lost_batches": 0, "rejected": 0, "never_stored": 0, "cores": {}}
        r = {**r, "ingest_grayscale": zero, "fill_grayscale": zero, "ingest_grayscale_per_s": 0.0,
             "bytes_per_transition_grayscale": 0.0, "grayscale_obs": {"shape": ["-"], "dtype": "skipped"}}
    cfg, v, g = r["config"], r["ingest_vector"], r["ingest_grayscale"]
    yes = lambda ok: "met" if ok else "NOT met"  # noqa: E731
    vs, gs = "x".join(map(str, r["vector_obs"]["shape"])), "x".join(map(str, r["grayscale_obs"]["shape"]))
    lines = [
        f"replay bench: {cfg['topology']}; zenoh {cfg['zenoh']}, {cfg['cpus']} cpus, loopback",
        f"  replay servers: config defaults" + "".join(f", {k}={v}" for k, v in (cfg.get("replay_set") or {}).items())
        + f"; run dirs under {cfg.get('work_dir', '?')}",
        f"  {cfg['duration_s']:g} s per window after {cfg['warmup_s']:g} s warm-up, {cfg['batch']} transitions per "
        f"message, actors spread over {cfg['publisher_processes']} publisher processes, CongestionControl.BLOCK",
        "",
        "ingest (transitions stored by the server per second, 2 actors, steady state)",
        f"  vector    {r['vector_obs']['dtype']} ({vs}): {r['ingest_vector_per_s']:>10,.0f} /s   "
        f"target >= {r['targets']['ingest_vector_per_s']:,}: {yes(r['met']['ingest_vector'])}",
        f"  grayscale {r['grayscale_obs']['dtype']} ({gs}): {r['ingest_grayscale_per_s']:>8,.0f} /s   "
        f"({r['ingest_grayscale_per_s'] * r['bytes_per_transition_grayscale'] / 1e6:,.0f} MB/s stored)",
        f"  first fill of the table (every write on a fresh page): vector {r['fill_vector']['ingest_per_s']:,.0f} /s, "
        f"grayscale {r['fill_grayscale']['ingest_per_s']:,.0f} /s; the rates above are after it (ring wrapping)",
        f"  lost batches {v['lost_batches']} / {g['lost_batches']}, rejected {v['rejected']} / {g['rejected']}, "
        f"sent but never stored {v['never_stored']} / {g['never_stored']} (vector / grayscale)",
        "",
        f"sample latency, SampleRequest({cfg['sample_batch']}) on vector data, query to decoded batch",
        f"  {'idle server:':33s} p50 {r['sample_p50_ms']:.2f} ms  p99 {r['sample_p99_ms']:.2f} ms  "
        f"(n={r['sample_idle']['n']}, reply {r['sample_idle']['reply_bytes']:,} B)   "
        f"target p99 <= {r['targets']['sample_p99_ms']:g} ms: {yes(r['met']['sample_p99'])}",
        *_loaded_lines(r),
        "",
        f"memory per stored transition (online table bytes / capacity): "
        f"vector {r['bytes_per_transition_vector']:,.0f} B, grayscale {r['bytes_per_transition_grayscale']:,.0f} B",
        "",
        "actor scaling (vector): cores = server/router/publishers/other processes on the machine",
        f"  {'actors':>6s} {'transitions/s':>14s} {'us/transition':>14s} {'server CPU us/tr':>16s} {'msgs/s':>9s} "
        f"{'lost':>5s} {'rejected':>8s} {'never stored':>12s}  cores",
    ]
    for row in r["actor_scaling"]:
        us = "-" if row["us_per_transition"] is None else f"{row['us_per_transition']:.2f}"
        cpu = "-" if row["server_cpu_us_per_transition"] is None else f"{row['server_cpu_us_per_transition']:.2f}"
        lines.append(f"  {row['actors']:>6d} {row['ingest_per_s']:>14,.0f} {us:>14s} {cpu:>16s} "
                     f"{row['messages_per_s']:>9,.0f} {row['lost_batches']:>5d} {row['rejected']:>8d} "
                     f"{str(row['never_stored']):>12s}  {_cores(row['cores'])}")
    lines.append(f"\ncores during the 2-actor vector window: {_cores(v['cores'])}; grayscale: {_cores(g['cores'])}")
    lines.append(f"total wall time {r['wall_s']:.0f} s")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "_publish":
        raise SystemExit(_publisher_main(sys.argv[2:]))
    raise SystemExit(main(sys.argv[1:]))
