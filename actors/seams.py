"""The env worker's seams (Acme style): what the same ``EnvWorker`` needs from the world, over
zenoh or in-process alike. Types, and the one weights decoding both adapters share
(``weights_update``); the zenoh adapter is in ``links``, the in-process one in
``laneshift.deploy.inprocess``, and the links own the encoding: every value crossing a seam is
typed, never the wire's bytes.

- ``ExperienceSink``: ``send_transitions(TransitionBatch)``, ``send_episode(EpisodeRecord)`` and
  ``flush() -> Delivery`` (at the end of the worker's run: wait, bounded, until the replay server
  holds every batch sent, sending again what it lacks; after a stop the wait is short, a couple
  of seconds. The ``Delivery`` says what the server had not confirmed then: the worker counts
  it lost and says so, never silently);
- ``WeightsSource`` (Acme's VariableSource): ``latest_weights()`` (the newest unseen version,
  never blocks) and ``wait_weights(timeout)``, each a ``WeightsUpdate``: the decoded
  ``wire.Weights`` (version, rehearsal phase, update count, tensors by state-dict name), a
  ``wire.WireError`` for a message that could not be read (the worker counts it and keeps the
  weights it has), or None (nothing new). While a worker waits for weights (sync mode: after
  each batch) the link also checks what the replay server holds and sends again what it lacks,
  so a lost batch never stalls a round;
- ``RunControl``: ``wait_insert_ok()`` (blocks while the replay's rate limiter says the learner is
  behind) and ``stop_requested() -> bool``;
- ``ActorLinks``: all three as one object (what the builder hands a worker).

Room: actors, the env-running component. May import: the contract; never another component.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, TypeAlias

from laneshift import wire

#: What a weights seam returns: new weights, a message that could not be read, or nothing new.
WeightsUpdate: TypeAlias = wire.Weights | wire.WireError | None


def weights_update(data: bytes | None) -> WeightsUpdate:
    """A WEIGHTS message decoded; the WireError of one that cannot be read (the worker counts it)."""
    if data is None:
        return None
    try:
        return wire.decode_weights(data)
    except wire.WireError as exc:
        return exc


@dataclass(frozen=True)
class Delivery:
    """What a flush left undelivered: the batches (and their items) the replay server had not
    confirmed holding when the flush ended. Nothing is sent again after it: the worker counts them
    lost. (A server too slow to answer in time may hold some after all; the run's own lost count
    is the server's record, so it stays exact either way.)"""

    undelivered_batches: int = 0
    undelivered_items: int = 0

    @property
    def complete(self) -> bool:
        """True when the replay server holds every batch sent."""
        return self.undelivered_batches == 0


class ExperienceSink(Protocol):
    """Where experience goes: the replay server (transitions) and the learner (episode records)."""

    def send_transitions(self, batch: wire.TransitionBatch) -> None: ...
    def send_episode(self, record: wire.EpisodeRecord) -> None: ...
    def flush(self) -> Delivery: ...


class WeightsSource(Protocol):
    """The learner's newest weights, decoded by the link."""

    def latest_weights(self) -> WeightsUpdate: ...
    def wait_weights(self, timeout: float) -> WeightsUpdate: ...


class RunControl(Protocol):
    """The run's flow control (the replay's rate limiter) and its stop."""

    def wait_insert_ok(self) -> None: ...
    def stop_requested(self) -> bool: ...


class ActorLinks(ExperienceSink, WeightsSource, RunControl, Protocol):
    """All three seams, as one object (what the builder hands a worker)."""
