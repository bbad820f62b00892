"""`laneshift bench replay`: replay-server ingest and sample speed over zenoh on loopback.

What runs is the topology `laneshift train --local` gives users: a `laneshift router` process and
a `laneshift replay-server` process as its client (straight scenario, vector or grayscale
observations, ``replay.samples_per_insert 0`` so the rate limiter never throttles, ``min_size 1``).
Synthetic actors are separate OS processes (``laneshift.tools.bench.replay_publisher``), each a zenoh
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

The pieces: this module (the command and the measurements), ``replay_publisher`` (a synthetic-actor
process), ``replay_harness`` (synthetic messages, timing; shared with ``bench shards``),
``cpu_meter`` (CPU per process) and ``replay_report`` (the text form).

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
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

from laneshift import transport, wire
from laneshift.tools.argtypes import parse_set
from laneshift.config import ConfigError, ReplayConfig, TransportConfig, load_run_config
from laneshift.progress import progress
from laneshift.progress import write as progress_write

from .cpu_meter import CpuMeter
from .replay_harness import SAMPLE_BATCH, BenchError, time_calls, wait_for_router
from .replay_report import format_result

TARGET_INGEST_VECTOR_PER_S = 200_000
TARGET_SAMPLE_P99_MS = 5.0
FILL_TIMEOUT_S = 300


# ----------------------------------------------------------------------------- CLI


def register(subparsers: Any) -> None:
    """Add the ``replay`` sub-command (``laneshift.tools.cli`` calls this under ``laneshift bench``)."""
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


# ----------------------------------------------------------------------------- the benchmark


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
            argv = [sys.executable, "-m", "laneshift.tools.bench.replay_publisher", "--router", self.endpoint,
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
            meter = CpuMeter({"server": [self.group.procs[run_id].pid], "router": [self.group.procs["router"].pid],
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


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
