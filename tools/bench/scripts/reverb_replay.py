"""DeepMind Reverb as a replay service: the peer of ``laneshift bench shards --shards 1``.

What it is: a standalone benchmark, so that laneshift's replay ingest rate and sample latency are
reported beside a peer's (``laneshift bench all``: ``vs_reverb_*``, ``reverb_*``). The same load as
laneshift's replay benchmark, on Reverb 0.14 (the replay service Acme uses):

- one ``reverb.Server`` process with one table of ``--capacity`` items: uniform sampler, FIFO
  remover, ``MinSize(1)`` rate limiter (laneshift's bench runs with ``samples_per_insert 0``, no
  throttle), no checkpointing;
- ``--actors`` writers spread over ``--writers`` processes; each writer appends the vector
  transition of laneshift's straight scenario (obs float32[82], action int32, reward float32,
  next_obs float32[82], terminated bool, steps uint8) and makes one item per transition, flushing
  every ``--batch`` items (laneshift's publishers send ``--batch`` transitions per message);
- ingest: items inserted per second over a window (the table's insert count against the server
  process's clock), once the table is full (fresh pages, as laneshift's bench does);
- sample latency: batches of 256 from a ``reverb.TimestepDataset`` of the table (Reverb's fast
  path, as Acme's learners sample), turned into numpy, from this process, under the writers'
  load and then idle;
- CPU per role (server, writers) from /proc over the ingest window.

One difference to keep in mind: laneshift's publishers send pre-encoded messages, Reverb's writers
serialise in their own process; both are measured at the server, and the writers' CPU is shown.

It prints ONE JSON object on stdout (progress on stderr). Run it in its own venv, which
``make bench-reverb`` builds (dm-reverb 0.14 with tensorflow-cpu 2.15, whose numpy<2 laneshift's
venv does not share):

    make bench-reverb
    .venv-reverb/bin/python tools/bench/scripts/reverb_replay.py --batch 32 --duration 3

Room: benchmarks (a peer, run in its own venv). May import: the standard library, numpy, reverb and tensorflow (Reverb's dataset). Nothing of laneshift (its venv has
none of laneshift's dependencies).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time

OBS = 82
SAMPLE = 256


def _say(msg: str) -> None:
    print(f"[reverb bench] {msg}", file=sys.stderr, flush=True)


def _table(capacity: int):
    import reverb

    return reverb.Table("replay", sampler=reverb.selectors.Uniform(), remover=reverb.selectors.Fifo(),
                        max_size=capacity, rate_limiter=reverb.rate_limiters.MinSize(1))


def _server_main(capacity: int, port_q: "mp.Queue", stop: "mp.Event") -> None:
    import reverb

    server = reverb.Server(tables=[_table(capacity)], port=None)
    port_q.put(server.port)
    stop.wait()
    server.stop()


def _steps(n: int, seed: int) -> list[dict]:
    """``n`` transitions of laneshift's straight-scenario vector schema, as Reverb steps."""
    import numpy as np

    rng = np.random.default_rng(seed)
    return [{"obs": rng.standard_normal(OBS, dtype=np.float32), "action": np.int32(rng.integers(9)),
             "reward": np.float32(rng.standard_normal()), "next_obs": rng.standard_normal(OBS, dtype=np.float32),
             "terminated": np.bool_(False), "steps": np.uint8(1)} for _ in range(n)]


def _writer_main(address: str, actors: int, batch: int, seed: int, go: "mp.Event", stop: "mp.Event",
                 sent: "mp.Value") -> None:
    import numpy as np
    import reverb

    steps = _steps(batch, seed)
    client = reverb.Client(address)
    # Reverb's legacy Writer: 165 us per item here against 234 for trajectory_writer (measured in
    # one process, 5,000 items each), so the peer gets the faster of its two writers. (chunk_length
    # 32 with one-step items was tried too: the table did not fill in 300 s.)
    writers = [client.writer(max_sequence_length=1) for _ in range(actors)]
    go.wait()
    n = 0
    while not stop.is_set():
        for w in writers:  # round robin over this process's actors, a message's worth each
            for step in steps:
                w.append(step)
                w.create_item("replay", 1, 1.0)
            w.flush()
            n += batch
    for w in writers:
        w.close()
    with sent.get_lock():
        sent.value += n


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _batches(address: str):
    """Reverb's fast sampling path, as Acme's learners use it: a TimestepDataset of the table,
    batched by 256, with 2 x 256 samples in flight (``Client.sample`` of 256 items took ~120 ms
    here: one gRPC stream and a Python object per item)."""
    import numpy as np
    import reverb
    import tensorflow as tf

    step = _steps(1, 0)[0]
    ds = reverb.TimestepDataset(server_address=address, table="replay",
                                dtypes={k: tf.as_dtype(np.asarray(v).dtype) for k, v in step.items()},
                                shapes={k: tf.TensorShape(np.asarray(v).shape) for k, v in step.items()},
                                max_in_flight_samples_per_worker=2 * SAMPLE).batch(SAMPLE)
    return iter(ds)


def _latency(batches, duration: float, warmup: int = 5, min_n: int = 20) -> dict:
    """Seconds per batch of 256 taken from the dataset and turned into numpy arrays."""
    import numpy as np

    def once() -> float:
        t = time.perf_counter()
        got = {k: v.numpy() for k, v in next(batches).data.items()}
        dt = time.perf_counter() - t
        if len(got["action"]) != SAMPLE:
            raise RuntimeError(f"sampled {len(got['action'])} items, not {SAMPLE}")
        return dt

    for _ in range(warmup):
        once()
    times, end = [], time.monotonic() + duration
    while time.monotonic() < end or len(times) < min_n:
        times.append(once())
    ms = np.array(times) * 1000
    return {"n": len(ms), "p50_ms": round(float(np.percentile(ms, 50)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3), "max_ms": round(float(ms.max()), 3)}


def _inserted(client) -> int:
    return int(client.server_info()["replay"].rate_limiter_info.insert_stats.completed)


def bench(args: argparse.Namespace) -> dict:
    import numpy as np
    import reverb

    ctx = mp.get_context("spawn")  # no forked copies of TF's threads
    port_q, stop_server = ctx.Queue(), ctx.Event()
    server = ctx.Process(target=_server_main, args=(args.capacity, port_q, stop_server), daemon=True)
    server.start()
    address = f"localhost:{port_q.get(timeout=120)}"
    go, stop_writers, sent = ctx.Event(), ctx.Event(), ctx.Value("q", 0)
    per = [len(range(j, args.actors, args.writers)) for j in range(args.writers)]
    writers = [ctx.Process(target=_writer_main, args=(address, n, args.batch, j, go, stop_writers, sent), daemon=True)
               for j, n in enumerate(per) if n]
    try:
        for w in writers:
            w.start()
        client = reverb.Client(address)
        _say(f"server {address}; {args.actors} actors over {len(writers)} writer processes, {args.batch} per flush")
        go.set()
        deadline = time.monotonic() + 300
        while _inserted(client) < args.capacity:
            if time.monotonic() > deadline:
                raise RuntimeError("the table did not fill in 300 s")
            time.sleep(0.1)
        _say("table full; measuring ingest")
        pids = {"server": [server.pid], "writers": [w.pid for w in writers]}
        cpu0 = {k: sum(_cpu_s(p) for p in v) for k, v in pids.items()}
        n0, t0 = _inserted(client), time.monotonic()
        time.sleep(args.duration)
        n1, t1 = _inserted(client), time.monotonic()
        cores = {k: round((sum(_cpu_s(p) for p in v) - cpu0[k]) / (t1 - t0), 2) for k, v in pids.items()}
        ingest = (n1 - n0) / (t1 - t0)
        batches = _batches(address)
        loaded = _latency(batches, args.duration)
        stop_writers.set()
        for w in writers:
            w.join(60)
        time.sleep(0.5)
        idle = _latency(batches, args.duration)
        stored = _inserted(client)
        info = client.server_info()["replay"]
        return {"peer": "reverb", "reverb": getattr(reverb, "__version__", "0.14.0"), "numpy": np.__version__,
                "python": sys.version.split()[0], "cpus": os.cpu_count(), "actors": args.actors,
                "writers": len(writers), "batch": args.batch, "capacity": args.capacity,
                "ingest_per_s": round(ingest, 1),
                "server_cpu_us_per_transition": round(cores["server"] * 1e6 / ingest, 2) if ingest else None,
                "cores_under_ingest": cores, "sample_idle": idle, "sample_under_ingest": loaded,
                "sent": sent.value, "inserted": stored, "never_stored": sent.value - stored,
                "table_size": int(info.current_size)}
    finally:
        stop_writers.set()
        for w in writers:
            w.join(10)
            if w.is_alive():
                w.kill()
        stop_server.set()
        server.join(30)
        if server.is_alive():
            server.kill()


def main() -> int:
    p = argparse.ArgumentParser(description="Reverb replay ingest and sample latency (laneshift's peer)")
    p.add_argument("--actors", type=int, default=8)
    p.add_argument("--writers", type=int, default=2, help="writer processes the actors are spread over")
    p.add_argument("--batch", type=int, default=32, help="items per flush (laneshift: transitions per message)")
    p.add_argument("--capacity", type=int, default=400_000)
    p.add_argument("--duration", type=float, default=3.0, help="seconds per measurement window")
    args = p.parse_args()
    print(json.dumps(bench(args)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
