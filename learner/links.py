"""The learner's links over zenoh: the seams of ``seams`` (``ReplayClient``, ``WeightsPublisher``,
``RunChannel``, as one ``LearnerLinks``) built on a zenoh session.

- ``ZenohReplayShard``: one replay server's ``ReplayShardClient`` (queries on its namespace's keys);
- ``ZenohLearnerLinks``: the learner's ``LearnerLinks``: the replay through one ``ZenohReplayShard``
  (or ``shards.ShardedReplay`` over one per shard), weights encoded and published with BLOCK and
  served to late joiners, the workers' episode records decoded, the learner's status published
  as its stats message, and the run's stop.

Every message the learner sends or takes is encoded or decoded here; the loop sees typed values.

Room: learner (component). May import: the contract and laneshift.learner (``seams``, ``shards``,
``episodes``, ``status``); never another component.
"""

from __future__ import annotations

import collections
import threading
from typing import TYPE_CHECKING, TypeVar

import zenoh

from laneshift import transport, wire
from laneshift.config import RunConfig

from .episodes import read_record
from .seams import EpisodeUpdate, PendingSample, ReplayClient, ReplayForwarding
from .shards import replay_over

if TYPE_CHECKING:
    from .status import LearnerStatus

T = TypeVar("T")


class ZenohReplayShard:
    """A ``ReplayClient`` for one replay server over zenoh: its keys are built from ``namespace``
    (the run id, or ``<run>/shard-<i>``: ``wire.replay_namespace``)."""

    def __init__(self, session: zenoh.Session, namespace: str, schema: wire.TransitionSchema, timeout_s: float,
                 router: str):
        self.session, self.namespace, self.schema, self.timeout = session, namespace, schema, timeout_s
        self._priorities = transport.data_publisher(session, wire.priorities_key(namespace))
        self._ask_sample = transport.Requester(session, wire.sample_key(namespace), timeout_s)
        # No answer from the replay server (not started yet, restarting, another run_id) is said in
        # one line after a few seconds, every 30 s while it lasts, and once when it answers.
        self.replay_wait = transport.WaitReporter(
            "learner", f"the replay server on {wire.sample_key(namespace)} (router {router})",
            f"the replay server answered on {wire.sample_key(namespace)} (router {router})")

    def _answered(self, reply: T) -> T:
        """Note whether the replay server answered (any reply, an ERROR too, is an answer)."""
        if reply is None:
            self.replay_wait.missed()
        else:
            self.replay_wait.answered()
        return reply

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch | wire.WireError | None:
        return self.request_sample(req)()

    def request_sample(self, req: wire.SampleRequest) -> PendingSample:
        pending = self._ask_sample.start(wire.encode_sample_request(req))

        def reply() -> wire.SampledBatch | wire.WireError | None:
            data = self._answered(pending())
            if data is None or isinstance(data, wire.WireError):
                return data
            return wire.decode_batch(data, self.schema)

        return reply

    def replay_stats(self) -> dict | None:
        reply = self._answered(transport.query(self.session, wire.replay_stats_key(self.namespace), b"",
                                               self.timeout))
        return _json_or_none(reply)

    def set_phase(self, phase: int) -> bool:
        reply = self._answered(transport.query(self.session, wire.replay_control_key(self.namespace),
                                               wire.encode_json({"cmd": "set_phase", "phase": phase}), self.timeout))
        body = _json_or_none(reply)
        return bool(body and body.get("ok"))

    def send_priorities(self, update: wire.PriorityUpdate) -> None:
        self._priorities.put(wire.encode_priorities(update))  # the one place a priority update is encoded


class ZenohLearnerLinks(ReplayForwarding):
    """LearnerLinks over zenoh: queries to the replay server (or, with ``replay.shards`` > 1, to
    every shard through ``ShardedReplay``), weights published with BLOCK."""

    def __init__(self, session: zenoh.Session, cfg: RunConfig, schema: wire.TransitionSchema,
                 stop: threading.Event):
        self.session, self.schema = session, schema
        self.run_id, self.timeout = cfg.transport.run_id, cfg.transport.timeout_s
        self._latest = b""
        self._pub = transport.data_publisher(session, wire.weights_key(self.run_id))
        # Late joiners and reconnecting actors ask for the newest weights here.
        transport.serve_queries(session, wire.weights_latest_key(self.run_id), lambda _: self._latest, stop,
                                "weights-latest")
        self._episodes: collections.deque[bytes] = collections.deque(maxlen=10_000)
        self._ep_sub = session.declare_subscriber(wire.episodes_wildcard(self.run_id),
                                                  lambda s: self._episodes.append(s.payload.to_bytes()))
        self._stop = transport.StopSignal(session, wire.control_key(self.run_id))
        self._stats_pub = session.declare_publisher(wire.learner_stats_key(self.run_id))
        n = cfg.replay.shards
        shards = [ZenohReplayShard(session, wire.replay_namespace(self.run_id, i, n), schema, self.timeout,
                                   cfg.transport.router) for i in range(n)]
        self.replay: ReplayClient = replay_over(shards, beta=cfg.replay.priority_beta, seed=cfg.learner.seed)

    def publish_weights(self, weights: wire.Weights) -> None:
        payload = wire.encode_weights(weights)  # the one place the learner's weights are encoded
        self._latest = payload
        self._pub.put(payload)

    def publish_stats(self, status: LearnerStatus, final: bool = False) -> None:
        self._stats_pub.put(wire.encode_json(status.stats_message(final)))

    def take_episodes(self) -> list[EpisodeUpdate]:
        out = []
        while self._episodes:
            out.append(read_record(self._episodes.popleft()))
        return out

    def stop_requested(self) -> bool:
        return self._stop.requested()

    def stop_all(self) -> None:
        """Broadcast the run-wide stop (actors and this learner end their loops)."""
        self.session.put(wire.control_key(self.run_id), wire.encode_json({"cmd": "stop"}))


def _json_or_none(reply: bytes | None) -> dict | None:
    """A reply that is missing, an ERROR message or not a JSON object reads as 'no answer':
    the learner retries later instead of dying of one bad reply."""
    if reply is None:
        return None
    try:
        body = wire.decode_json(reply)
    except wire.WireError:
        return None
    return body if isinstance(body, dict) else None
