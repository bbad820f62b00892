"""``laneshift train``: one launcher for local and cluster mode; read it as the diagram.

    router        (RouterActor, zenoh, on a node offering deploy.router_resources; in local mode
                   a session in this process instead: deploy.router_in)
      ^ replay    (ReplayServerActor: tables, demo shard, checkpoints, HTTP API on its node)
      ^ learner   (LearnerActor: Double DQN on learner.device, weights out, full-state checkpoints)
      ^ w0..wN-1  (EnvWorkerActor: envs, epsilon-greedy, transitions every K steps)
    this process  Ray driver: places the actors, supervises them, shows progress, summarises

Every component is a Ray actor built by ``deploy.builder.Builder`` (a local run's router excepted:
this process hosts it, since a local run's Ray processes die with it anyway), placed with its
resources and restarted by Ray up to ``deploy.max_restarts`` times; this launcher notices a death (the
actor's ``run()`` call fails), says so, and calls ``run()`` again on the restarted actor, which
resumes from its checkpoint (replay table, learner state) or from what the replay server stored
of it (an env worker's steps and sequence numbers). Local mode is a private Ray cluster (state
in a temp dir, no token, loopback only); cluster mode joins a running cluster (``--cluster``,
``RAY_ADDRESS``, ``ray job submit``). SIGTERM and SIGINT end the run gracefully at any moment:
final learner and replay checkpoints, summary, nothing left running.

This module is the entry point (``train``); its helpers: ``supervision`` (the run's actors: start,
supervision, stop), ``stop_signals`` (SIGTERM and SIGINT), ``progress_line`` (the live status line),
``run_dir`` (the run dir's lock, resume/overwrite, the default demo shard), ``ray_connection`` (the
private or the running Ray cluster), ``summary`` (the end of the run).

Room: deploy, the wiring. May import: the contract, ``deploy``'s own modules, Ray; components
only through the builder.
"""

from __future__ import annotations

import dataclasses
import json
import signal
import sys
import time
from pathlib import Path
from typing import TextIO

from laneshift.config import RunConfig

from .errors import LaunchError
from .pinning import own_cpus, resolve_learner_core, restore_own_cpus
from .ray_connection import RayConnection
from .run_dir import RunDirLock, SpaceReserve, ensure_demo_shard, prepare_run_dir
from .spec_process import SpecProcess
from .stop_signals import StopSignals
from .summary import summarise
from .supervision import Run


def train(cfg: RunConfig, *, address: str | None = None, out: TextIO = sys.stdout, resume: bool = False,
          overwrite: bool = False) -> int:
    """A whole training run. ``address`` None: a private local Ray cluster; else that cluster's.
    Returns 0 (done), 1 (failed), 130 (SIGINT) or 143 (SIGTERM) after a graceful stop."""
    signals = StopSignals().install()  # from the very start: a SIGTERM before Ray is a clean exit too
    started = time.monotonic()
    run_dir = Path(cfg.train.run_dir).resolve()
    cfg = cfg.replace(train=dataclasses.replace(cfg.train, run_dir=str(run_dir)),
                      # Runs serve the HTTP inspection API on a free loopback port unless told otherwise,
                      # and the learner's Prometheus /metrics too.
                      replay=cfg.replay if cfg.replay.http_port != -1 else dataclasses.replace(cfg.replay, http_port=0),
                      learner=cfg.learner if cfg.learner.metrics_port != -1
                      else dataclasses.replace(cfg.learner, metrics_port=0))
    lock = RunDirLock(run_dir)
    reserve = SpaceReserve(run_dir)
    ray_conn = RayConnection(address)
    launcher_cpus = own_cpus()  # Run.start may move this process off the learner's CPU
    run: Run | None = None
    spec_child: SpecProcess | None = None
    rc = 1
    try:
        lock.acquire()
        prepare_run_dir(run_dir, resume, overwrite, out)
        reserve.hold(out)
        # The env's spec, computed here once while Ray starts (Ray's start is mostly waiting), is
        # shipped to the replay server and the learner, which then build no simulator of their own.
        spec_child = SpecProcess(cfg)
        ray_conn.open(cfg)  # contacted and authenticated before anything starts
        ray_s = time.monotonic() - started
        signals.install()  # replace Ray's SIGTERM handler (it would abort the cleanup after ~3 s)
        if signals.received:
            raise KeyboardInterrupt
        cfg = ensure_demo_shard(cfg, out)
        if signals.received:
            raise KeyboardInterrupt
        cfg = cfg.replace(deploy=dataclasses.replace(  # auto -> a CPU in local mode, off on a cluster
            cfg.deploy, learner_core=resolve_learner_core(cfg.deploy.learner_core, local=address is None)))
        run = Run(cfg, local=address is None, out=out, signals=signals)
        run.env_spec = spec_child.result()
        run.start()
        run._say(f"train: started in {time.monotonic() - started:.1f} s (Ray {ray_s:.1f} s, router "
                 f"{run.timeline['router']:.1f} s, replay server, learner and workers {run.timeline['rest']:.1f} s)")
        why = run.supervise()
        if why != "done":
            run._say(f"train: {why} received; stopping gracefully (checkpoints, summary)")
        run.stop()
        # Their processes end before the summary's greedy eval builds an env here (highway-env,
        # pygame, matplotlib: about 70 MB): the run's peak memory is then its training's.
        run.kill_all()
        if run.progress.tty:
            out.write("\n")
        reserve.release()  # the room kept for the end records below
        result = summarise(run.ended(), why, time.monotonic() - started, out)
        write_end_records(run_dir, result, run.replay_finals, out)
        rc = {"done": 0, "SIGINT": 130, "SIGTERM": 143}.get(why, 0)
    except LaunchError as exc:
        print(f"\ntrain: {exc}", file=out, flush=True)
        if run is not None:
            run.stop(graceful_s=30)
        rc = 1
    except KeyboardInterrupt:
        print("\ntrain: interrupted; stopping every component", file=out, flush=True)
        if run is not None and signals.received:
            run.stop(graceful_s=30)
        rc = 130 if signals.received != signal.SIGTERM else 143
    finally:
        reserve.release()
        if spec_child is not None:
            spec_child.close()
        if run is not None:
            run.kill_all()
            run.close_router()
        ray_conn.close()
        lock.release()
        signals.restore()
        restore_own_cpus(launcher_cpus)
    return rc


def write_end_records(run_dir: Path, result: dict, replay_finals: dict[str, dict], out: TextIO) -> None:
    """``summary.json``, and each replay server's final stats that the server could not write itself
    (a full run dir: it counted the failure, and the launcher holds the same stats). A file that
    cannot be written is said in one line: the summary printed above is then all there is."""
    files = {"summary.json": result, **{name: stats for name, stats in replay_finals.items()
                                        if not _json_file(run_dir / name)}}
    for name, body in files.items():
        try:
            (run_dir / name).write_text(json.dumps(body, indent=2))
        except OSError as exc:
            print(f"train: could not write {run_dir / name}: {exc}", file=out, flush=True)


def _json_file(path: Path) -> bool:
    """``path`` holds a whole JSON document (not missing, not cut short by a full disk)."""
    try:
        json.loads(path.read_text())
        return True
    except (OSError, ValueError):
        return False
