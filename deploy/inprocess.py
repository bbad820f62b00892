"""The same component graph in one process, for unit tests and debugging (no Ray, no zenoh).

What it is: the in-process runner. The components come from the same ``deploy.builder.Builder``
as in local and cluster mode; only where they run differs: workers and the learner are threads
talking through in-memory links to a ReplayCore (one per shard with ``replay.shards`` > 1, each
worker sending to its shard and the learner sampling all through ``learner.shards.ShardedReplay``,
as over zenoh). The links are the seams' in-memory adapters (``actors.seams``, ``learner.seams``):
typed values at the seams, and every message still goes through the wire encoder and decoder
in between, so the contract is exercised as in a real run.
Room: deploy, the wiring. May import: the contract, ``deploy.builder``, the workers' seams
(``actors.seams``) and the learner's (``learner.seams``, ``learner.shards``, ``learner.episodes``,
``learner.status``).

    >>> from laneshift.config import load_run_config
    >>> cfg = load_run_config(overrides={"env.scenario": "lka", "train.env_steps": 2000})  # doctest: +SKIP
    >>> result = train_inprocess(cfg)  # doctest: +SKIP
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from laneshift import wire
from laneshift.actors.seams import Delivery, WeightsUpdate, weights_update
from laneshift.config import RunConfig
from laneshift.learner.episodes import read_record
from laneshift.learner.seams import EpisodeUpdate, PendingSample, ReplayForwarding
from laneshift.learner.shards import replay_over

if TYPE_CHECKING:
    from laneshift.learner.status import LearnerStatus

from .builder import Builder


@dataclass
class Board:
    """What the zenoh router carries in a real run: the newest weights, episodes, stop."""

    cores: list  # laneshift.replay_server.core.ReplayCore, one per replay shard
    stop: threading.Event = field(default_factory=threading.Event)
    cond: threading.Condition = field(default_factory=threading.Condition)
    weights: bytes = b""  # the newest WEIGHTS message, as the learner's links encoded it
    episodes: collections.deque = field(default_factory=lambda: collections.deque(maxlen=10_000))
    learner_stats: dict = field(default_factory=dict)


class InProcessActorLinks:
    """A worker's ``ActorLinks`` on the board: batches into its shard's core, weights decoded."""

    def __init__(self, board: Board, name: str):
        self.board, self.name = board, name
        self.core = board.cores[wire.shard_of(name, len(board.cores))]  # this worker's replay shard
        self._seen = b""

    def send_transitions(self, batch: wire.TransitionBatch) -> None:
        self.core.ingest(wire.encode_transitions(batch), self.name)  # the wire's bytes, as over zenoh

    def send_episode(self, record: wire.EpisodeRecord) -> None:
        self.board.episodes.append(wire.encode_episode(record))

    def flush(self) -> Delivery:
        return Delivery()  # send_transitions stored it before returning

    def latest_weights(self) -> WeightsUpdate:
        with self.board.cond:
            if not self.board.weights or self.board.weights is self._seen:
                return None
            self._seen = self.board.weights
        return weights_update(self._seen)  # each worker decodes, as over zenoh

    def wait_weights(self, timeout: float) -> WeightsUpdate:
        with self.board.cond:
            if self.board.weights is self._seen:
                self.board.cond.wait(timeout)
        return self.latest_weights()

    def wait_insert_ok(self) -> None:
        while not self.core.insert_allowed() and not self.board.stop.wait(0.001):
            pass

    def stop_requested(self) -> bool:
        return self.board.stop.is_set()


class InProcessReplay:
    """A ``ReplayClient`` for one in-memory ReplayCore (requests and replies as wire bytes)."""

    def __init__(self, core: Any, schema: wire.TransitionSchema):
        self.core, self.schema = core, schema

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch | wire.WireError | None:
        reply = self.core.handle_sample_query(wire.encode_sample_request(req))
        if wire.peek_kind(reply) == wire.Kind.ERROR:
            return wire.decode_error(reply)
        return wire.decode_batch(reply, self.schema)

    def request_sample(self, req: wire.SampleRequest) -> PendingSample:
        """In one process there is nothing to overlap: the sample is drawn now."""
        batch = self.sample(req)
        return lambda: batch

    def send_priorities(self, update: wire.PriorityUpdate) -> None:
        self.core.handle_priorities(wire.encode_priorities(update))  # the core takes the message as sent

    def replay_stats(self) -> dict | None:
        return self.core.stats()

    def set_phase(self, phase: int) -> bool:
        reply = self.core.handle_control({"cmd": "set_phase", "phase": phase})
        return bool(reply and reply.get("ok"))


class InProcessLearnerLinks(ReplayForwarding):
    """The learner's ``LearnerLinks`` on the board: weights and stats encoded, episodes decoded."""

    def __init__(self, board: Board, schema: wire.TransitionSchema, beta: float = 0.4, seed: int = 0):
        self.board, self.schema = board, schema
        shards = [InProcessReplay(core, schema) for core in board.cores]
        self.replay = replay_over(shards, beta=beta, seed=seed)

    def publish_weights(self, weights: wire.Weights) -> None:
        payload = wire.encode_weights(weights)  # encoded now: the tensors are views of the network
        with self.board.cond:
            self.board.weights = payload
            self.board.cond.notify_all()

    def publish_stats(self, status: LearnerStatus, final: bool = False) -> None:
        self.board.learner_stats = wire.decode_json(wire.encode_json(status.stats_message(final)))

    def take_episodes(self) -> list[EpisodeUpdate]:
        out = []
        while self.board.episodes:
            out.append(read_record(self.board.episodes.popleft()))
        return out

    def stop_requested(self) -> bool:
        return False  # stopped through the shared event

    def stop_all(self) -> None:
        self.board.stop.set()


def train_inprocess(cfg: RunConfig, stop: threading.Event | None = None) -> dict:
    """Run workers and learner as threads until the env-step budget is spent, or until ``stop`` is
    set (a caller's deadline: the workers end their loops, then the learner writes its final
    checkpoint as at the budget's end); returns a summary."""
    builder = Builder(cfg)
    board = Board(cores=[builder.replay_core(i) for i in range(cfg.replay.shards)], stop=stop or threading.Event())
    learner_stop = threading.Event()
    links = InProcessLearnerLinks(board, builder.spec.schema, cfg.replay.priority_beta, cfg.learner.seed)
    learner = builder.learner(links, learner_stop)
    learner_thread = threading.Thread(target=learner.run, name="learner", daemon=True)
    learner_thread.start()
    names, share = builder.workers, builder.budgets
    summaries: dict[str, dict] = {}

    def work(i: int, name: str) -> None:
        worker = builder.env_worker(i)
        try:
            summaries[name] = worker.run(InProcessActorLinks(board, name), share[i]).as_dict()
        finally:
            worker.close()

    threads = [threading.Thread(target=work, args=(i, n), name=n, daemon=True) for i, n in enumerate(names)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    learner_stop.set()
    board.stop.set()
    learner_thread.join(timeout=60)
    from laneshift.replay_stats import merge_replay_stats

    replay = merge_replay_stats([core.stats(all_actors=True) for core in board.cores], all_actors=True)
    return {"workers": [summaries[n] for n in names if n in summaries], "replay": replay,
            "learner": board.learner_stats, "updates": learner.agent.updates, "version": learner.version}
