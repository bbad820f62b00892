"""`laneshift bench shards`: a sharded replay's ingest and sample latency for 1, 2, 4 ... shards.

What runs is what ``laneshift train`` with ``replay.shards`` N gives users: one ``laneshift router``
process and N ``laneshift replay-server --shard i`` processes (vector observations of the straight
scenario, ``samples_per_insert 0`` so no rate limiter throttles, no periodic checkpoint).
Synthetic actors (``--actors``, named ``a0``, ``a1``, ...) are spread over ``--publishers``
processes; each actor publishes pre-encoded TRANSITIONS (``replay_harness.synthetic_message``) to
its shard (``wire.shard_of``), as fast as BLOCK lets it. Measured for each shard count:

- ingest: transitions/s **stored** over a window, summed over every shard (each shard's
  ``tables.online.inserted`` against its own clock), and how evenly the shards took them;
- CPU per process role (servers, router, publishers, this process) over the ingest window, from
  /proc, and the servers' and router's CPU per stored transition;
- sample latency: ``SampleRequest(256)`` through the learner's own client (one
  ``learner.links.ZenohReplayShard``, or ``learner.shards.ShardedReplay`` over one per shard:
  every shard asked before any reply is awaited, merge, shuffle), idle and under saturating
  ingest (a second window);
- the transport's floor beside it (``floor_*``): the same client asking N queryables (one per
  shard, each in a process of its own, ``ShardedReplay`` over them as over the shards) that answer
  every request with one fixed BATCH (the same bytes a shard sends, prepared once), so the
  servers' own work is nil. What sample latency the router, zenoh, N processes answering at once,
  the client's decode and merge and the machine's scheduling leave, idle and under the same ingest.

    laneshift bench shards --shards 1,2,4 --json

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from laneshift import transport, wire
from laneshift.config import TransportConfig
from laneshift.progress import write as progress_write

from .cpu_meter import CpuMeter
from .replay_harness import (MESSAGES_PER_ACTOR, SAMPLE_BATCH, BenchError, check_alive, stop_publishers, synthetic_message,
                             time_calls, wait_for_router, wait_ready)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("shards", help="a sharded replay's ingest and sample latency for 1, 2, 4 shards")
    _add_arguments(p)
    p.set_defaults(func=run)


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--shards", default="1,2,4", help="shard counts to measure (default 1,2,4)")
    p.add_argument("--actors", type=int, default=8, help="synthetic actors (default 8: 2 per shard at 4 shards)")
    p.add_argument("--publishers", type=int, default=2, help="publisher processes the actors are spread over")
    p.add_argument("--batch", type=int, default=32, help="transitions per message (default 32)")
    p.add_argument("--capacity", type=int, default=400_000, help="replay.capacity over all shards")
    p.add_argument("--duration", type=float, default=3.0, help="seconds per measurement window")
    p.add_argument("--netns", default="",
                   help="network namespaces NS1,NS2,...: the router in NS1, shard i and publisher j in the "
                        "namespace i (j) mod their count, as on that many hosts (root; run this command in NS1; "
                        "tools/bench/scripts/twohost_shards.py makes two and runs it)")
    p.add_argument("--router-ip", default="127.0.0.1",
                   help="the address the router listens on and every process connects to (with --netns: NS1's)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")


def run(args: argparse.Namespace) -> int:
    try:
        result = bench(args)
    except BenchError as exc:
        print(f"bench shards: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(result, indent=2) if args.json else format_result(result), flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "_publish":
        return _publisher_main(argv[1:])
    if argv and argv[0] == "_floor":
        return _floor_main(argv[1:])
    p = argparse.ArgumentParser(prog="python -m laneshift.tools.bench.shards")
    _add_arguments(p)
    return run(p.parse_args(argv))


def _publisher_main(argv: list[str]) -> int:
    """Synthetic actors of one process: each publishes to its shard, round robin, until SIGTERM."""
    p = argparse.ArgumentParser(prog="python -m laneshift.tools.bench.shards _publish")
    for name in ("--router", "--run-id", "--actors", "--ready", "--go", "--report"):
        p.add_argument(name, required=True)
    p.add_argument("--shards", type=int, required=True)
    p.add_argument("--batch", type=int, required=True)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    schema = _vector_schema()
    actors = a.actors.split(",")
    rng = np.random.default_rng(a.seed)
    patchers = [[synthetic_message(actor, schema, a.batch, rng) for _ in range(MESSAGES_PER_ACTOR)] for actor in actors]
    sent = [0] * len(actors)
    with transport.open_session(TransportConfig(router=a.router, run_id=a.run_id)) as session:
        pubs = [transport.data_publisher(session, wire.transitions_key(
            wire.replay_namespace(a.run_id, wire.shard_of(actor, a.shards), a.shards), actor)) for actor in actors]
        if not transport.wait_for(lambda: stop.is_set() or all(x.matching_status.matching for x in pubs), 60,
                                  interval_s=0.01) or stop.is_set():
            return 3
        Path(a.ready).write_text("ready")
        parent, go = os.getppid(), Path(a.go)
        while not go.exists():
            if stop.is_set() or os.getppid() != parent:
                return 0
            time.sleep(0.005)
        while not stop.is_set() and os.getppid() == parent:
            for k, pub in enumerate(pubs):
                s = sent[k]
                pub.put(patchers[k][s % MESSAGES_PER_ACTOR].build(s, (s + 1) * a.batch))
                sent[k] = s + 1
        Path(a.report).write_text(json.dumps({actor: n * a.batch for actor, n in zip(actors, sent)}))
        time.sleep(0.1)  # let zenoh's transmit queue drain before the session closes
    return 0


FLOOR_NAMESPACE = "bench-floor"


def floor_namespace(i: int) -> str:
    """Zero-work queryable ``i``'s namespace (``FLOOR_NAMESPACE`` itself for the first)."""
    return FLOOR_NAMESPACE if i == 0 else f"{FLOOR_NAMESPACE}-{i}"


def _floor_main(argv: list[str]) -> int:
    """A queryable on ``floor_namespace(--index)``'s sample key that answers with one prepared
    BATCH of ``--rows`` rows, opened as a replay server opens its query session, until SIGTERM."""
    p = argparse.ArgumentParser(prog="python -m laneshift.tools.bench.shards _floor")
    for name in ("--router", "--ready"):
        p.add_argument(name, required=True)
    p.add_argument("--index", type=int, default=0)
    p.add_argument("--rows", type=int, default=SAMPLE_BATCH, help="rows of the prepared reply (a shard's part)")
    a = p.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    from .learner import Case, sampled_batch

    schema = _vector_schema()
    reply = bytes(wire.encode_batch(sampled_batch(Case("floor", schema.obs_shape, "float32", a.rows), 1, seed=a.index)))
    transport.use_service_runtime()
    with transport.open_session(TransportConfig(router=a.router), batching=False) as session:
        transport.serve_queries(session, wire.sample_key(floor_namespace(a.index)), lambda _: reply, stop, "floor")
        Path(a.ready).write_text("ready")
        parent = os.getppid()
        while not stop.wait(0.2) and os.getppid() == parent:
            pass
    return 0


def _vector_schema() -> wire.TransitionSchema:
    from laneshift.actors.envs import spec_of
    from laneshift.config import EnvConfig

    return spec_of(EnvConfig(scenario="straight", observation="vector")).schema


class _ShardBench:
    """One router; for each shard count, N replay servers, publishers, and the learner's client."""

    def __init__(self, args: argparse.Namespace, work: Path, log: TextIO):
        from laneshift.deploy.processes import ProcessGroup

        self.args, self.work, self.log = args, work, log
        self.endpoint = f"tcp/{args.router_ip}:{transport.free_tcp_port()}"
        self.group = ProcessGroup(work / "logs")
        self.py = [sys.executable, "-m", "laneshift"]
        self.namespaces = [ns for ns in str(args.netns).split(",") if ns.strip()]
        self.t0 = time.monotonic()
        self.schema = _vector_schema()

    def host(self, i: int) -> list[str]:
        """The argv prefix that starts process ``i`` of a kind on "host" i mod the namespaces' count
        (``ip netns exec`` execs the command: its pid is the process's own)."""
        return ["ip", "netns", "exec", self.namespaces[i % len(self.namespaces)]] if self.namespaces else []

    def say(self, msg: str) -> None:
        progress_write(f"[bench shards {time.monotonic() - self.t0:5.1f}s] {msg}", file=self.log)

    def start_router(self) -> None:
        self.group.start("router", [*self.host(0), *self.py, "router", "--listen", self.endpoint])
        wait_for_router(self.endpoint, self.check_router)

    def start_floors(self, shards: int) -> list[str]:
        """One zero-work queryable (``_floor_main``) per shard, each where that shard runs, each
        answering with a shard's part of a request (SAMPLE_BATCH / shards rows, as ``split_rows``
        gives them at equal sizes)."""
        from laneshift.learner.shards import split_rows

        names = []
        for i, rows in enumerate(split_rows(SAMPLE_BATCH, [1.0] * shards)):
            name = f"floor{shards}-{i}"
            self.group.start(name, [*self.host(i), sys.executable, "-m", "laneshift.tools.bench.shards", "_floor",
                                    "--router", self.endpoint, "--ready", str(self.work / f"{name}.ready"),
                                    "--index", str(i), "--rows", str(rows)])
            names.append(name)
        wait_ready(self.group, {name: self.work / f"{name}.ready" for name in names}, 60)
        return names

    def check_router(self) -> None:
        check_alive(self.group, ["router"])

    def start_servers(self, run_id: str, shards: int) -> list[str]:
        from laneshift.config import load_run_config, save_run_config

        cfg = load_run_config(overrides={
            "env.scenario": "straight", "env.observation": "vector", "replay.capacity": self.args.capacity,
            "replay.samples_per_insert": 0, "replay.min_size": shards, "replay.shards": shards,
            "replay.checkpoint_every_s": 0, "replay.restore": False, "transport.router": self.endpoint,
            "transport.run_id": run_id, "train.run_dir": str(self.work / run_id)})
        path = save_run_config(cfg, self.work / f"{run_id}.yaml")
        names = []
        for i in range(shards):
            name, ready = f"{run_id}-s{i}", self.work / f"{run_id}-s{i}.ready"
            self.group.start(name, [*self.host(i), *self.py, "replay-server", "--config", str(path), "--shard", str(i),
                                    "--ready-file", str(ready)])
            names.append(name)
        wait_ready(self.group, {name: self.work / f"{name}.ready" for name in names}, 120)
        return names

    def stop(self, names: list[str]) -> None:
        for name in names:  # SIGKILL: the tables are throwaway (a clean stop would checkpoint them)
            proc = self.group.procs[name]
            if proc.poll() is None:
                proc.kill()
                proc.wait(30)

    def start_publishers(self, run_id: str, shards: int) -> list[dict]:
        a = self.args
        actors = [f"a{i}" for i in range(a.actors)]
        pubs = []
        for j in range(min(a.publishers, len(actors))):
            tag = f"{run_id}-pub{j}"
            files = {k: self.work / f"{tag}.{k}" for k in ("ready", "go", "report")}
            argv = [*self.host(j), sys.executable, "-m", "laneshift.tools.bench.shards", "_publish", "--router", self.endpoint,
                    "--run-id", run_id, "--shards", str(shards), "--actors", ",".join(actors[j::a.publishers]),
                    "--batch", str(a.batch), "--seed", str(j), *(x for k, f in files.items() for x in (f"--{k}", str(f)))]
            pubs.append({"name": tag, "proc": self.group.start(tag, argv), **files})
        wait_ready(self.group, {pub["name"]: pub["ready"] for pub in pubs}, 60, lambda: self.stop_publishers(pubs))
        return pubs

    def stop_publishers(self, pubs: list[dict]) -> dict[str, int]:
        """Every publisher stopped; how many transitions each actor sent (actors of a publisher that
        left no report are missing)."""
        sent: dict[str, int] = {}
        for report in stop_publishers(self.group, pubs).values():
            sent.update(report or {})
        return sent

    def measure(self, shards: int) -> dict:
        from laneshift.learner.links import ZenohReplayShard
        from laneshift.learner.shards import replay_over

        a = self.args
        run_id = f"shards{shards}"
        servers = self.start_servers(run_id, shards)
        names = servers + self.start_floors(shards)
        pubs: list[dict] = []
        try:
            # The learner's client, opened as the learner opens its session (unbatched).
            client_cfg = TransportConfig(router=self.endpoint, run_id=run_id)
            with transport.open_session(client_cfg, batching=False) as session:
                clients = [ZenohReplayShard(session, wire.replay_namespace(run_id, i, shards), self.schema, 10.0,
                                            self.endpoint) for i in range(shards)]
                replay = replay_over(clients)
                floors = [ZenohReplayShard(session, floor_namespace(i), self.schema, 10.0, self.endpoint)
                          for i in range(shards)]
                floor = replay_over(floors)

                def stats() -> list[dict]:
                    out = [c.replay_stats() for c in clients]
                    if any(s is None for s in out):
                        raise BenchError(f"a replay shard of {run_id} did not answer a stats query")
                    return out  # type: ignore[return-value]

                pubs = self.start_publishers(run_id, shards)
                for pub in pubs:  # fill the tables once (fresh pages), then measure
                    pub["go"].write_text("go")
                fill_deadline = time.monotonic() + 300
                while sum(s["tables"]["online"]["inserted"] for s in stats()) < a.capacity:
                    if time.monotonic() > fill_deadline:
                        raise BenchError(f"{run_id}: the tables did not fill in 300 s")
                    time.sleep(0.1)
                # Window 1: ingest alone (the rate and its CPU); window 2: sample latency under it.
                meter = CpuMeter({"servers": [self.group.procs[n].pid for n in servers],
                                   "router": [self.group.procs["router"].pid],
                                   "publishers": [p["proc"].pid for p in pubs]})
                s0 = stats()
                time.sleep(a.duration)
                s1 = stats()
                cores = meter.cores()
                loaded = _latency(replay, a.duration)
                floor_loaded = _latency(floor, a.duration)
                sent = self.stop_publishers(pubs)
                pubs = []
                per_shard = [(b["tables"]["online"]["inserted"] - x["tables"]["online"]["inserted"])
                             / max(b["uptime_s"] - x["uptime_s"], 1e-9) for x, b in zip(s0, s1)]
                time.sleep(0.5)  # the servers drain their queues, then idle
                idle = _latency(replay, a.duration)
                floor_idle = _latency(floor, a.duration)
                end = stats()
                lost = sum(int(s["actors_total"]["lost_batches"]) for s in end)
                stored = sum(int(s["actors_total"]["items"]) for s in end)
                rejected = sum(sum(s["rejected"].values()) for s in end)
            server_us = cores.get("servers") and sum(per_shard) and cores["servers"] * 1e6 / sum(per_shard)
            router_us = cores.get("router") and sum(per_shard) and cores["router"] * 1e6 / sum(per_shard)
            return {"shards": shards, "ingest_per_s": round(sum(per_shard), 1),
                    # CPU per stored transition, which other load on the machine cannot skew.
                    "server_cpu_us_per_transition": round(server_us, 2) if server_us else None,
                    "router_cpu_us_per_transition": round(router_us, 2) if router_us else None,
                    "ingest_per_shard": [round(r, 1) for r in per_shard], "sample_idle": idle,
                    "sample_under_ingest": loaded, "floor_idle": floor_idle, "floor_under_ingest": floor_loaded,
                    "cores_under_ingest": cores,
                    "sent": sum(sent.values()) if sent else None, "stored": stored,
                    "never_stored": (sum(sent.values()) - stored) if sent else None,
                    "lost_batches": lost, "rejected": rejected}
        finally:
            if pubs:
                self.stop_publishers(pubs)
            self.stop(names)


def _latency(replay: Any, duration: float, warmup: int = 10, min_n: int = 20) -> dict:
    """``SampleRequest(256)`` round trips through the learner's client, decoded (and, sharded, merged)."""
    req = wire.SampleRequest(SAMPLE_BATCH)

    def once() -> float:
        t = time.perf_counter()
        batch = replay.sample(req)
        dt = time.perf_counter() - t
        if not isinstance(batch, wire.SampledBatch) or len(batch.action) != SAMPLE_BATCH:
            raise BenchError(f"sample refused or short: {batch!r:.200}")
        return dt

    return time_calls(once, duration, warmup, min_n)


def bench(args: argparse.Namespace, log: TextIO = sys.stderr) -> dict:
    counts = [int(x) for x in str(args.shards).split(",") if x.strip()]
    if not counts or min(counts) < 1 or max(counts) > wire.MAX_SHARDS:
        raise BenchError(f"--shards {args.shards}: counts between 1 and {wire.MAX_SHARDS}")
    work = Path(tempfile.mkdtemp(prefix="ls-bench-shards-"))
    b = _ShardBench(args, work, log)
    old_term = signal.signal(signal.SIGTERM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt()))
    try:
        b.start_router()
        rows = []
        for n in counts:
            b.say(f"{n} shard(s): {args.actors} actors over {args.publishers} publisher processes")
            rows.append(b.measure(n))
            row = rows[-1]
            b.say(f"{n} shard(s): {row['ingest_per_s']:,.0f} transitions/s stored; sample p99 "
                  f"{row['sample_idle']['p99_ms']} ms idle, {row['sample_under_ingest']['p99_ms']} ms under ingest "
                  f"(the transport's floor: {row['floor_idle']['p99_ms']} and {row['floor_under_ingest']['p99_ms']} ms)")
        return {"bench": "shards", "batch": args.batch, "actors": args.actors, "publishers": args.publishers,
                "capacity": args.capacity, "cpus": os.cpu_count(), "netns": b.namespaces, "router": b.endpoint,
                "rows": rows}
    finally:
        b.group.stop_all()
        signal.signal(signal.SIGTERM, old_term)
        shutil.rmtree(work, ignore_errors=True)


def format_result(r: dict) -> str:
    lines = [f"sharded replay: {r['actors']} actors over {r['publishers']} publisher processes, {r['batch']} "
             f"transitions per message, capacity {r['capacity']:,} over all shards, {r['cpus']} CPUs"
             + (f"; namespaces {', '.join(r['netns'])} (router {r['router']})" if r.get("netns") else ""),
             f"{'shards':>6} {'stored/s':>10} {'per shard':>26} {'idle p50/p99 ms':>16} {'ingest p50/p99 ms':>18}"
             f" {'floor p99 idle/ingest':>21} {'lost':>5} {'never stored':>12} {'us/tr server':>12} {'router':>7}"
             f"   cores servers/router/publishers/other"]
    for row in r["rows"]:
        c = row["cores_under_ingest"]
        lines.append(f"{row['shards']:>6} {row['ingest_per_s']:>10,.0f} {', '.join(f'{x:,.0f}' for x in row['ingest_per_shard']):>26}"
                     f" {row['sample_idle']['p50_ms']:>7.2f}/{row['sample_idle']['p99_ms']:<8.2f}"
                     f" {row['sample_under_ingest']['p50_ms']:>8.2f}/{row['sample_under_ingest']['p99_ms']:<9.2f}"
                     f" {row['floor_idle']['p99_ms']:>10.2f}/{row['floor_under_ingest']['p99_ms']:<10.2f}"
                     f" {row['lost_batches']:>5} {row['never_stored'] if row['never_stored'] is not None else '-':>12}"
                     f" {row['server_cpu_us_per_transition'] or '-':>12} {row['router_cpu_us_per_transition'] or '-':>7}"
                     f"   {c.get('servers')}/{c.get('router')}/{c.get('publishers')}/{c.get('other')}")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
