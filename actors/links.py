"""The worker's seams (``seams.ActorLinks``) over zenoh: transitions out (BLOCK, held until the
replay server has them, sent again if it lacks them), newest weights in (decoded here: the worker
gets ``wire.Weights``, or the ``wire.WireError`` of a message it cannot read), control in. The
encoding and decoding of every message the worker sends or takes is here.

    >>> links = ZenohActorLinks(session, "run", "w0")  # doctest: +SKIP
    >>> worker.run(links, env_steps=10_000)  # doctest: +SKIP

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import collections
import time

import zenoh

from laneshift import transport, wire

from .seams import Delivery, WeightsUpdate, weights_update


#: Batches a worker may have sent that the replay server has not stored yet, and how often
#: (in batches) it asks: a bound on what a cut link can queue, at one query per 16 batches. The
#: worker keeps those batches' bytes (at most this many: 64 x a batch, e.g. 64 x 1.8 MB for
#: 32 grayscale 84x84x4 items, 64 x 4 KB for the LKA plant) until the server has them, and sends
#: again whatever the server's answer shows it lacks, so a replay server killed with -9 (its log
#: keeps what it took) or a link reset loses nothing.
MAX_IN_FLIGHT = 64
ACK_EVERY = 16
#: No progress on the batches after the server's newest for this long (doubling while it lasts,
#: up to RESEND_MAX_S): sent again, as they may have died on the way (nothing after them shows a gap).
RESEND_AFTER_S = 2.0
RESEND_MAX_S = 30.0
#: How long a worker whose budget is spent waits for the server to hold all it sent (a replay
#: server that restarts takes a few seconds; it is given much more).
FLUSH_TIMEOUT_S = 120.0
#: After a stop (the launcher's graceful end) a flush waits at most this long, and sends again
#: what the server lacks once nothing was put for STOP_RESEND_AFTER_S (the worker sends nothing
#: new then, so a batch still missing is lost on the way, not late). What the server still lacks
#: at the end is lost and counted (``seams.Delivery``).
STOP_FLUSH_S = 2.0
STOP_RESEND_AFTER_S = 0.5
#: While a worker waits for weights (sync mode: after each batch, for the round that batch is part
#: of) with batches unacknowledged, it asks the server at most this often, and sends again what it
#: lacks once nothing was put for RESEND_AFTER_S: a lost batch would otherwise stall the round
#: (the next query was due ACK_EVERY batches later, and the worker sends none while it waits).
WAIT_ACK_EVERY_S = 0.5


class ZenohActorLinks:
    def __init__(self, session: zenoh.Session, run_id: str, name: str, timeout_s: float = 5.0, shards: int = 1):
        self.session, self.run_id, self.timeout_s = session, run_id, timeout_s
        # This worker's replay server: the run's one, or with replay.shards > 1 the shard its name
        # routes to (wire.shard_of), always the same, so a restarted worker finds its state there.
        self.shard = wire.shard_of(name, shards)
        replay = self.replay_ns = wire.replay_namespace(run_id, self.shard, shards)
        self._transitions = transport.data_publisher(session, wire.transitions_key(replay, name))
        self._episodes = transport.data_publisher(session, wire.episodes_key(run_id, name))
        self._weights = transport.LatestValue(session, wire.weights_key(run_id))
        self._stop = transport.StopSignal(session, wire.control_key(run_id))
        self._flow = transport.LatestValue(session, wire.replay_flow_key(replay))
        self._insert_ok = True
        self._last_query = 0.0
        self.name = name
        self._sent = 0  # batches sent by this session (resends not counted)
        # Sent, not yet known stored: seq -> (the message's bytes, its items), oldest first (at
        # most MAX_IN_FLIGHT).
        self._unacked: collections.OrderedDict[int, tuple[bytes, int]] = collections.OrderedDict()
        self._last_ack = 0.0  # when the server was last asked what it holds
        self._put_at = 0.0  # when the last batch was put (sent or sent again)
        self._next_seq = 0  # the seq after the last one sent
        self._server: str | None = None  # the replay server process that answered last
        self._progress = (-1, time.monotonic(), RESEND_AFTER_S)  # (its next_seq, since when, resend after)
        self.resent = 0  # batches sent again (counted; the server ignores those it has)
        # A wait on the network says so in the worker's log: one line after a few seconds, then at
        # most one every 30 s, and one when it is over (transport.WaitReporter).
        router = transport.router_of(session)
        self._weights_wait = transport.WaitReporter(
            name, f"the learner's weights on {wire.weights_key(run_id)} (router {router})", "got the learner's weights")
        self._flow_wait = transport.WaitReporter(
            name, f"the replay server to allow inserts on {wire.replay_flow_key(replay)} (rate limiter; "
                  f"router {router})", "the replay server allows inserts again")
        self._replay_wait = transport.WaitReporter(
            name, f"the replay server on {wire.replay_control_key(replay)} (router {router})",
            f"the replay server answered on {wire.replay_control_key(replay)}")

    def send_transitions(self, batch: wire.TransitionBatch) -> None:
        payload = wire.encode_transitions(batch)
        if (self._sent % ACK_EVERY == 0 or len(self._unacked) >= MAX_IN_FLIGHT) and not self.stop_requested():
            self._bound_in_flight()  # (after a stop the flush that follows asks)
        self._put(payload)
        self._unacked[batch.seq] = (payload, len(batch))
        self._next_seq = batch.seq + 1
        self._sent += 1

    def _put(self, payload: bytes, wait_s: float | None = None) -> None:
        if not self._transitions.matching_status.matching:
            # Nobody subscribed as far as this session knows (the first batch, or the router or
            # replay server is coming back): a put now would go nowhere, so wait for the match
            # (bounded: after timeout_s, or ``wait_s``, it is sent anyway; it stays held and is
            # sent again).
            transport.wait_matching(self._transitions, self.timeout_s if wait_s is None else wait_s)
        self._transitions.put(payload)
        self._put_at = time.monotonic()

    def stored_state(self) -> dict[str, int] | None:
        """What the replay server stored of this worker: ``{"env_steps", "next_seq"}`` (zeros for
        a worker it never saw), or None when it did not answer. A restarted worker resumes there."""
        body = self._ask({"cmd": "actor_state", "actor": self.name})
        return {"env_steps": int(body["env_steps"]), "next_seq": int(body["next_seq"])} if body else None

    def wait_stored_state(self, timeout_s: float, router: str = "") -> dict[str, int]:
        """``stored_state``, asked again until the replay server answers (it may still be starting);
        TimeoutError after ``timeout_s`` (naming ``router``, the endpoint this session went through).
        Where a worker process starts its share."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            state = self.stored_state()
            if state is not None:
                return state
            time.sleep(0.2)
        raise TimeoutError(f"{self.name}: the replay server did not answer within {timeout_s:.0f} s"
                           + (f" (router {router})" if router else ""))

    def _ask(self, command: dict, timeout_s: float | None = None) -> dict | None:
        reply = transport.query(self.session, wire.replay_control_key(self.replay_ns), wire.encode_json(command),
                                self.timeout_s if timeout_s is None else timeout_s)
        if reply is None:
            self._replay_wait.missed()
        else:
            self._replay_wait.answered()
        try:
            body = wire.decode_json(reply) if reply is not None else {}
        except wire.WireError:
            return None
        return body if body.get("ok") else None

    def acknowledge(self, timeout_s: float | None = None, idle_s: float | None = None) -> bool | None:
        """Ask the replay server what it holds of this worker's batches; forget those it has; send
        again those it lacks: the seqs it counted lost (a link reset, a restart whose log ended
        before them), and, when nothing after them shows a gap (the server restarted, or no
        progress for RESEND_AFTER_S, or, with ``idle_s``, nothing put for that long: the worker
        has stopped sending), every batch after its newest. True when nothing is left
        unacknowledged, None when the server did not answer. ``timeout_s`` bounds the query and
        each resend's wait for a subscriber (the links' ``timeout_s`` when None)."""
        unacked = self._unacked
        self._last_ack = time.monotonic()
        body = self._ask({"cmd": "actor_state", "actor": self.name,
                          "from_seq": next(iter(unacked)) if unacked else self._next_seq}, timeout_s)
        if body is None:
            return None
        next_seq, missing = int(body["next_seq"]), {int(s) for s in body.get("missing", ())}
        for seq in [s for s in unacked if s < next_seq and s not in missing]:
            del unacked[seq]
        again = sorted(s for s in missing if s in unacked)
        tail = [s for s in unacked if s >= next_seq]
        server, now = body.get("server"), time.monotonic()
        seen, since, after = self._progress
        if next_seq != seen or not tail:
            self._progress = (next_seq, now, RESEND_AFTER_S)
        elif now - since >= after:  # stalled: the tail may have died on the way
            again += tail
            self._progress = (next_seq, now, min(2 * after, RESEND_MAX_S))
        if idle_s is not None and now - self._put_at >= idle_s:  # nothing is on its way: what it lacks is lost
            again += tail
        if server != self._server:
            if self._server is not None:  # a new server process: what was on its way to the old one is gone
                again += tail
            self._server = server
        for seq in sorted(set(again)):
            self._put(unacked[seq][0], timeout_s)
            self.resent += 1
        return not unacked

    def _bound_in_flight(self) -> None:
        """Wait while MAX_IN_FLIGHT of this worker's batches are sent but not stored.

        The rate limiter only sees what arrived; on a cut link a worker ran 10,000 steps ahead of
        what was stored. A query every ACK_EVERY batches keeps what it holds (and the memory
        queued behind the link) bounded, and sends again what the server lacks.
        """
        self.acknowledge()
        while len(self._unacked) >= MAX_IN_FLIGHT and not self.stop_requested():
            time.sleep(0.05)
            self.acknowledge()

    def flush(self, timeout_s: float = FLUSH_TIMEOUT_S) -> Delivery:
        """At the end of the worker's run: wait (at most ``timeout_s``; once a stop is seen, at most
        STOP_FLUSH_S more) until the replay server holds every batch this worker sent, sending
        again what it lacks. The ``Delivery`` says what it still lacked then: lost (the replay's
        gaps and the launcher's count of the batches after the server's newest count them)."""
        deadline = time.monotonic() + timeout_s
        stopped = False
        while self._unacked:
            if not stopped and self.stop_requested():
                stopped = True  # a graceful end: a short wait, then the resends go out sooner
                deadline = min(deadline, time.monotonic() + STOP_FLUSH_S)
            left = deadline - time.monotonic()
            if left <= 0:
                break
            if self.acknowledge(timeout_s=min(self.timeout_s, max(left, 0.1)),
                                idle_s=STOP_RESEND_AFTER_S if stopped else None):
                break
            time.sleep(min(0.1, max(0.0, deadline - time.monotonic())))
        return Delivery(len(self._unacked), sum(items for _, items in self._unacked.values()))

    def send_episode(self, record: wire.EpisodeRecord) -> None:
        self._episodes.put(wire.encode_episode(record))

    def latest_weights(self) -> WeightsUpdate:
        return weights_update(self._weights.take())

    def wait_weights(self, timeout: float) -> WeightsUpdate:
        data = pushed = self._weights.wait(timeout)
        if data is None and time.monotonic() - self._last_query > 1.0:
            # Nothing pushed to us (we joined late, or reconnected): ask for the latest.
            self._last_query = time.monotonic()
            data = transport.query(self.session, wire.weights_latest_key(self.run_id), b"", self.timeout_s) or None
        if data is None:
            self._weights_wait.missed()
        else:
            self._weights_wait.answered()
        if pushed is None and self._unacked and time.monotonic() - self._last_ack >= WAIT_ACK_EVERY_S:
            # Still waiting (sync mode: for the round its last batch is part of). If that batch
            # was lost on the way, the round waits for it: ask what the server lacks, send it again.
            self.acknowledge(idle_s=RESEND_AFTER_S)
        return weights_update(data)

    def wait_insert_ok(self) -> None:
        """Block while the replay server says the learner is too far behind (rate limiter)."""
        self._update_flow(self._flow.take())
        if self._insert_ok:
            return
        while not self._insert_ok and not self.stop_requested():
            self._flow_wait.missed()
            self._update_flow(self._flow.wait(0.5))
        if self._insert_ok:
            self._flow_wait.answered()

    def _update_flow(self, data: bytes | None) -> None:
        if data is not None:
            try:
                self._insert_ok = bool(wire.decode_json(data).get("insert_ok", True))
            except wire.WireError:
                pass

    def stop_requested(self) -> bool:
        return self._stop.requested()

    def close(self) -> None:
        self._weights.close()
        self._stop.close()
        self._flow.close()
