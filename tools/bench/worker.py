"""``laneshift bench worker``: one env worker's env steps/s on one core, for 1, 4 and 16 envs.

What it is: the real ``EnvWorker`` (built by the one builder, as in every mode), acting
epsilon-greedily with a learner-shaped network and encoding every batch it sends, pinned to one
core; its links only count what it sends (nothing downstream is measured: the replay server and
the learner have their own benchmarks). Several envs per worker share one batched forward pass
per step, which is what the 4 and 16 rows show.
Room: the tools (benchmarks). May import: the contract, ``deploy``, the worker's seams (``actors.seams``) and the argparse types (``laneshift.tools.argtypes``).

    laneshift bench worker --envs 1,4,16 --steps 4000 --json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from laneshift import wire
from laneshift.actors.seams import Delivery
from laneshift.tools.argtypes import positive_int


class CountingLinks:
    """The worker's seams, answering at once: weights once, insert always allowed; counts bytes."""

    def __init__(self, weights: wire.Weights):
        self._weights: wire.Weights | None = weights
        self.batches = self.bytes = self.episodes = 0

    def send_transitions(self, batch: wire.TransitionBatch) -> None:
        self.batches += 1
        self.bytes += len(wire.encode_transitions(batch))  # the encoding is part of a worker's cost

    def send_episode(self, record: wire.EpisodeRecord) -> None:
        self.episodes += 1

    def flush(self) -> Delivery:
        return Delivery()

    def latest_weights(self) -> wire.Weights | None:
        w, self._weights = self._weights, None
        return w

    def wait_weights(self, timeout: float) -> wire.Weights | None:
        return self.latest_weights()

    def wait_insert_ok(self) -> None:
        return None

    def stop_requested(self) -> bool:
        return False


def bench_worker(scenario: str, envs: int, steps: int, epsilon: float = 0.1) -> dict:
    from laneshift.config import load_run_config
    from laneshift.qnet import build_q_network  # the learner's network, for its weights
    from laneshift.qnet import weights_of

    from laneshift.deploy.builder import Builder

    cfg = load_run_config(overrides={"env.scenario": scenario, "actor.workers": 1, "actor.envs_per_worker": envs,
                                     "actor.epsilon_start": epsilon, "actor.epsilon_final": epsilon})
    builder = Builder(cfg)
    worker = builder.env_worker(0)
    spec = builder.spec.schema
    net = build_q_network(spec.obs_shape, spec.n_actions, cfg.learner.hidden, cfg.learner.dueling,
                          cfg.learner.network_cnn, heads=cfg.learner.heads)
    links = CountingLinks(weights_of(net, 0, 0, 0))
    started, cpu = time.perf_counter(), time.process_time()
    summary = worker.run(links, steps)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    worker.close()
    return {"scenario": scenario, "envs_per_worker": envs, "env_steps": summary.env_steps, "wall_s": round(wall, 2),
            "env_steps_per_s": round(summary.env_steps / wall, 1),
            "env_steps_per_cpu_s": round(summary.env_steps / max(cpu, 1e-9), 1),
            "episodes": links.episodes, "batches": links.batches, "bytes_sent": links.bytes}


def bench_worker_main(args: argparse.Namespace) -> int:
    try:
        counts = [int(x) for x in args.envs.split(",") if x.strip()]
        if not counts or min(counts) < 1:
            raise ValueError
    except ValueError:
        print(f"bench worker: --envs takes positive integers separated by commas, got {args.envs!r}", file=sys.stderr)
        return 2
    if hasattr(os, "sched_setaffinity"):  # one core: "per core" means it
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    rows = [bench_worker(args.scenario, n, args.steps) for n in counts]
    if args.json:
        print(json.dumps({"rows": rows}, indent=2))
    else:
        print(f"{'envs/worker':>12}{'env steps/s':>13}{'per CPU s':>11}{'episodes':>10}")
        for r in rows:
            print(f"{r['envs_per_worker']:>12}{r['env_steps_per_s']:>13}{r['env_steps_per_cpu_s']:>11}{r['episodes']:>10}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("worker", help="one env worker's env steps/s on one core for several envs per worker",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scenario", default="straight", help="env.scenario of the worker's envs")
    p.add_argument("--envs", default="1,4,16", help="envs per worker to measure, comma-separated")
    p.add_argument("--steps", type=positive_int, default=4000, help="env steps per measurement (over all of the worker's envs)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=bench_worker_main)
