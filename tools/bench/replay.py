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

The pieces: this module (the command and the sequence of measurements), ``replay_rig`` (the
processes it runs and its measurement windows), ``replay_publisher`` (a synthetic-actor process),
``replay_harness`` (synthetic messages, readiness, timing; shared with ``bench shards``),
``cpu_meter`` (CPU per process) and ``replay_report`` (the text form).

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

from laneshift import transport, wire
from laneshift.config import ConfigError, TransportConfig, load_run_config
from laneshift.progress import progress
from laneshift.tools.argtypes import parse_set

from .replay_harness import SAMPLE_BATCH, BenchError
from .replay_report import format_result
from .replay_rig import ReplayRig

TARGET_INGEST_VECTOR_PER_S = 200_000
TARGET_SAMPLE_P99_MS = 5.0


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
    b = ReplayRig(args, work, log)
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
