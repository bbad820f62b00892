"""``laneshift replay-server``, ``laneshift learner``, ``laneshift worker`` and ``laneshift router``:
one process each (what a run's Ray actors run, as commands of their own: a run on a machine
without Ray, or under another supervisor), ended by ``end_service_process`` once it has stopped
cleanly.

Room: the tools (the laneshift command). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
from typing import TYPE_CHECKING, Any, NoReturn

from laneshift.tools.argtypes import add_config_args, config_from, endpoint, non_negative_int

if TYPE_CHECKING:
    from laneshift.actors.seams import ActorLinks


def end_service_process(rc: int) -> NoReturn:
    """End a service process (replay server, learner, router) once it has stopped cleanly: flush
    the std streams and ``os._exit(rc)``, skipping interpreter finalization.

    Why: zenoh-python is Rust (pyo3). A thread that returns from a zenoh call (a channel's
    ``recv()``, a session's ``close()`` that timed out) while CPython 3.11 finalizes is ended with
    ``pthread_exit``; its forced unwind is caught by pyo3's panic guard and glibc aborts the
    process ("FATAL: exception not rethrown", SIGABRT) after the final checkpoint and stats were
    written. CI saw it once on a replay server's SIGTERM. Every file the service writes is
    written and closed before this point, so finalization has nothing left to do for us."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken pipe: nothing more to say anyway
            pass
    os._exit(rc)


def _replay_server(args: argparse.Namespace) -> int:
    from laneshift.actors.envs import spec_of
    from laneshift.replay_server.service import run_replay_server

    cfg = config_from(args, {"replay.http_port": args.http_port, "replay.http_host": args.http_host})
    # The one env this process builds: to learn the observation's shape and the action count.
    return end_service_process(run_replay_server(cfg, spec_of(cfg.env), embedded_router=args.embedded_router,
                                                  ready_file=args.ready_file, shard=args.shard))


def _learner(args: argparse.Namespace) -> int:
    from laneshift.deploy.builder import Builder
    from laneshift.learner.process import run_learner

    builder = Builder(config_from(args))  # the env's spec and the periodic greedy evaluation
    return end_service_process(run_learner(builder.cfg, builder.spec, builder.greedy_evaluation()))


class _SignalStop:
    """A worker's links with SIGINT/SIGTERM as a stop request beside the run-wide stop message:
    the worker ends its loop, sends what its last batch holds and returns its summary."""

    def __init__(self, links: ActorLinks, stop: threading.Event):
        self._links, self._stop = links, stop

    def stop_requested(self) -> bool:
        return self._stop.is_set() or self._links.stop_requested()

    def __getattr__(self, name: str) -> Any:  # every other part of the seam, as the links have it
        return getattr(self._links, name)


def _worker(args: argparse.Namespace) -> int:
    import json
    import signal

    from laneshift import transport
    from laneshift.actors.worker import Resume
    from laneshift.deploy.builder import Builder

    builder = Builder(config_from(args))
    cfg = builder.cfg
    if args.index >= cfg.actor.workers:
        print(f"worker: --index {args.index}: actor.workers is {cfg.actor.workers} (indexes 0.."
              f"{cfg.actor.workers - 1})", file=sys.stderr)
        return 2
    name, budget = builder.workers[args.index], builder.budgets[args.index]
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    worker = builder.env_worker(args.index)
    rc = 0
    try:
        with transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes, who=name) as session:
            links = builder.actor_links(session, name)
            # A restarted worker goes on from what the replay server stored of it (a first start: zeros).
            state = links.wait_stored_state(cfg.deploy.start_timeout_s, cfg.transport.router)
            resume = Resume(env_steps=min(state["env_steps"], budget), next_seq=state["next_seq"])
            summary = worker.run(_SignalStop(links, stop), budget, resume).as_dict()
            print(json.dumps({**summary, "resumed_at": resume.env_steps, "resent": links.resent}), flush=True)
            links.close()
    except TimeoutError as exc:  # no replay server answered: one line naming the router
        print(f"worker: {exc}", file=sys.stderr, flush=True)
        rc = 1
    finally:
        worker.close()
    return end_service_process(rc)


def _router(args: argparse.Namespace) -> int:
    from laneshift.deploy.router import run_router

    return end_service_process(run_router(args.listen))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay-server", help="run the replay server process")
    add_config_args(p)
    p.add_argument("--embedded-router", action="store_true", help="be the zenoh router too (listen on transport.router)")
    p.add_argument("--ready-file", help="write this file once serving (used by the launcher)")
    p.add_argument("--http-port", type=non_negative_int,
                   help="serve the HTTP inspection API on this port (0 = a free one)")
    p.add_argument("--http-host", help="bind address of the HTTP API (default 127.0.0.1: loopback only)")
    p.add_argument("--shard", type=non_negative_int, default=0,
                   help="which shard of replay.shards this server is (default 0; a fixed HTTP port becomes "
                        "port + shard)")
    p.set_defaults(func=_replay_server)
    p = sub.add_parser("learner", help="run the learner process")
    add_config_args(p)
    p.set_defaults(func=_learner)
    p = sub.add_parser("worker", help="run one env worker process (its share of train.env_steps)")
    add_config_args(p)
    p.add_argument("--index", type=non_negative_int, required=True,
                   help="which of actor.workers this is (0 .. actor.workers - 1): its name, seed and share")
    p.set_defaults(func=_worker)
    p = sub.add_parser("router", help="run a zenoh router for the other processes")
    p.add_argument("--listen", type=endpoint, default="tcp/127.0.0.1:7447", help="zenoh endpoint to listen on")
    p.set_defaults(func=_router)
