"""The processes one ``laneshift bench replay`` runs and its measurement windows (``ReplayRig``):
a ``laneshift router`` process, ``laneshift replay-server`` processes as its clients (one config
each: the straight scenario, no rate limiter, no periodic checkpoint, ``--set`` last), publisher
processes of synthetic actors (``replay_publisher``), and this process's own zenoh session for the
stats and sample queries. ``ingest`` measures what a server stored over one window, ``settle``
waits for it to store what was sent, ``sample_latency`` times sample queries.

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from laneshift import transport, wire
from laneshift.config import ReplayConfig, load_run_config
from laneshift.progress import progress
from laneshift.progress import write as progress_write
from laneshift.tools.argtypes import parse_set

from .cpu_meter import CpuMeter
from .replay_harness import (SAMPLE_BATCH, BenchError, check_alive, stop_publishers, time_calls, wait_for_router,
                             wait_ready)

#: How long the first fill of a table may take.
FILL_TIMEOUT_S = 300


class ReplayRig:
    """One router, replay servers and publisher processes, and the measurements over them."""

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
        from laneshift.actors.envs import spec_of
        from laneshift.config import save_run_config

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
        wait_ready(self.group, {name: ready}, 120)
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
        check_alive(self.group, sorted(self.live))

    def start_publishers(self, run_id: str, schema: wire.TransitionSchema, names: list[str],
                         rate: float = 0.0) -> list[dict]:
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
        wait_ready(self.group, {pub["name"]: pub["ready"] for pub in pubs}, 60, lambda: self.stop_publishers(pubs))
        return pubs

    @staticmethod
    def go(pubs: list[dict]) -> None:
        """Release the start barrier of every publisher in ``pubs``."""
        for pub in pubs:
            pub["go"].write_text("go")

    def stop_publishers(self, pubs: list[dict]) -> dict[str, dict]:
        """Every publisher stopped; what each actor sent, from the publishers' reports."""
        for pub in pubs:
            self.live.discard(pub["name"])
        sent: dict[str, dict] = {}
        for name, report in stop_publishers(self.group, pubs).items():
            try:
                sent.update(report["actors"])
            except (TypeError, ValueError, KeyError):
                # Its actors count as "unknown sent" (never_stored: None); say why in the bench log.
                rc = self.group.procs[name].poll()
                self.say(f"publisher {name} left no report (exit {rc}); end of its log:\n{self.group.log_tail(name)}")
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
