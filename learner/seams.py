"""The learner's seams (Acme style): what the same Learner needs from the world, over zenoh or
in-process alike. Types only (and one forwarding helper); the zenoh adapters are in ``links``,
the sharded replay in ``shards``, and both import this module. Every value crossing a seam is
typed; the adapters own the encoding (the wire's bytes never reach the learner's loop).

- ``ReplayClient``: ``sample(SampleRequest)`` -> SampledBatch, a WireError (not ready / rate
  limited) or None; ``send_priorities(PriorityUpdate)`` (the |TD errors| of a sampled batch's rows,
  encoded by the adapter that puts it on the wire); ``replay_stats()``; ``set_phase(phase)``
  (one replay server: ``links.ZenohReplayShard``; several: ``shards.ShardedReplay`` over one
  each, a ``ReplayShardClient``, which can also send a request before waiting for it:
  ``request_sample``, returning a ``PendingSample``);
- ``WeightsPublisher``: ``publish_weights(wire.Weights)`` (the network's tensors with their
  version, rehearsal phase and update count: ``laneshift.qnet.weights_of``; the tensors may be
  views of the learner's network, so an adapter encodes them before it returns);
- ``RunChannel``: ``take_episodes()`` (the workers' episode records, each an ``EpisodeUpdate``:
  decoded by the adapter, or the ``wire.WireError`` of one that could not be read, which the
  learner counts), ``publish_stats(LearnerStatus, final)`` (``status.LearnerStatus``; the adapter
  sends ``to_dict()`` as JSON, with ``"done": true`` on the final one), ``stop_requested()``,
  ``stop_all()``;
- ``LearnerLinks``: all three as one object; ``ReplayForwarding``: the ``ReplayClient`` half of a
  LearnerLinks, forwarded to its ``replay``.

Room: learner (component). May import: the contract and, for its type, ``status``; never another
component.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol, TypeAlias

from laneshift import wire

if TYPE_CHECKING:  # the status module brings the learner's torch code; the seams stay types only
    from .status import LearnerStatus

# A sample request already sent: calling it waits for the reply (``ReplayShardClient.request_sample``).
PendingSample = Callable[[], "wire.SampledBatch | wire.WireError | None"]
#: One of the workers' episode records: decoded, or the error of one that could not be read.
EpisodeUpdate: TypeAlias = wire.EpisodeRecord | wire.WireError


class ReplayClient(Protocol):
    """The replay server, as the learner uses it."""

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch | wire.WireError | None: ...
    def send_priorities(self, update: wire.PriorityUpdate) -> None: ...
    def replay_stats(self) -> dict | None: ...
    def set_phase(self, phase: int) -> bool:
        """Rehearsal and DQfD: the replay server(s) to ``phase`` (2: online transitions join the
        demos); True once every one took it, False when one refused or did not answer."""
        ...


class ReplayShardClient(ReplayClient, Protocol):
    """One replay server of several: ``request_sample`` sends the request and returns the call
    that waits for its reply, so ``ShardedReplay`` asks every shard before it waits for any."""

    def request_sample(self, req: wire.SampleRequest) -> PendingSample: ...


class WeightsPublisher(Protocol):
    """The weights broadcast to the env workers."""

    def publish_weights(self, weights: wire.Weights) -> None: ...


class RunChannel(Protocol):
    """Episode records in, the learner's stats out, and the run's stop."""

    def take_episodes(self) -> list[EpisodeUpdate]: ...
    def publish_stats(self, status: LearnerStatus, final: bool = False) -> None: ...
    def stop_requested(self) -> bool: ...
    def stop_all(self) -> None: ...


class LearnerLinks(ReplayClient, WeightsPublisher, RunChannel, Protocol):
    """All three seams, as one object (what the builder hands the learner)."""


class ReplayForwarding:
    """The ``ReplayClient`` half of a LearnerLinks, handed on to ``self.replay``: one replay
    server's client, or ``ShardedReplay`` over one per shard (zenoh and in-process links alike)."""

    replay: ReplayClient

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch | wire.WireError | None:
        return self.replay.sample(req)

    def replay_stats(self) -> dict | None:
        return self.replay.replay_stats()

    def set_phase(self, phase: int) -> bool:
        return self.replay.set_phase(phase)

    def send_priorities(self, update: wire.PriorityUpdate) -> None:
        self.replay.send_priorities(update)
