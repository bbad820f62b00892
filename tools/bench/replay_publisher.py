"""One synthetic-actor process of ``bench replay`` (``python -m laneshift.tools.bench.replay_publisher``,
started by the bench): a zenoh client publishing pre-encoded TRANSITIONS for every actor key it is
given, round robin, as fast as ``CongestionControl.BLOCK`` lets it (or paced), from a start
barrier until SIGTERM; it reports what it sent in a JSON file.

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from laneshift import transport, wire
from laneshift.config import TransportConfig

from .replay_harness import MESSAGES_PER_ACTOR, synthetic_message

DRAIN_S = 0.1  # pause between the last put and closing the session (none lost without it, measured)


def main(argv: list[str]) -> int:
    """One synthetic-actor process: publishes for every actor key given, round robin, until SIGTERM."""
    p = argparse.ArgumentParser(prog="python -m laneshift.tools.bench.replay_publisher")
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


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
