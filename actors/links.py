"""The worker's seams over zenoh: transitions out (BLOCK), newest weights in, control in.

    >>> links = ZenohActorLinks(session, "run", "w0")  # doctest: +SKIP
    >>> worker.run(links, env_steps=10_000)  # doctest: +SKIP

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import time

import zenoh

from laneshift import transport, wire


#: Batches a worker may have sent that the replay server has not stored yet, and how often
#: (in batches) it asks: a bound on what a cut link can lose or queue, at one query per 16 batches.
MAX_IN_FLIGHT = 64
ACK_EVERY = 16


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
        self._sent = 0  # batches sent by this session
        self._base_seq: int | None = None  # the server's next_seq for us before our first batch
        # A wait on the network says so in the worker's log: one line after a few seconds, then at
        # most one every 30 s, and one when it is over (transport.WaitLines).
        router = transport.router_of(session)
        self._weights_wait = transport.WaitLines(
            name, f"the learner's weights on {wire.weights_key(run_id)} (router {router})", "got the learner's weights")
        self._flow_wait = transport.WaitLines(
            name, f"the replay server to allow inserts on {wire.replay_flow_key(replay)} (rate limiter; "
                  f"router {router})", "the replay server allows inserts again")
        self._replay_wait = transport.WaitLines(
            name, f"the replay server on {wire.replay_control_key(replay)} (router {router})",
            f"the replay server answered on {wire.replay_control_key(replay)}")

    def send_transitions(self, batch: wire.TransitionBatch) -> None:
        payload = wire.encode_transitions(batch)
        if not self._transitions.matching_status.matching:
            # Nobody subscribed as far as this session knows (the first batch, or the router or
            # replay server is coming back): a put now would go nowhere, so wait for the match
            # (bounded: after timeout_s it is sent anyway and the server counts the gap as lost).
            transport.wait_matching(self._transitions, self.timeout_s)
        if self._sent % ACK_EVERY == 0:
            self._bound_in_flight()
        self._transitions.put(payload)
        self._sent += 1

    def stored_state(self) -> dict[str, int] | None:
        """What the replay server stored of this worker: ``{"env_steps", "next_seq"}`` (zeros for
        a worker it never saw), or None when it did not answer. A restarted worker resumes there."""
        reply = transport.query(self.session, wire.replay_control_key(self.replay_ns),
                                wire.encode_json({"cmd": "actor_state", "actor": self.name}), self.timeout_s)
        if reply is None:
            self._replay_wait.missed()
        else:
            self._replay_wait.answered()
        try:
            body = wire.decode_json(reply) if reply is not None else {}
        except wire.WireError:
            return None
        return {"env_steps": int(body["env_steps"]), "next_seq": int(body["next_seq"])} if body.get("ok") else None

    def _stored_next_seq(self) -> int | None:
        state = self.stored_state()
        return state["next_seq"] if state is not None else None

    def _bound_in_flight(self) -> None:
        """Wait while more than MAX_IN_FLIGHT of this worker's batches are sent but not stored.

        The rate limiter only sees what arrived; on a cut link a worker ran 10,000 steps ahead of
        what was stored, and lost them all when its budget ended during the cut. A query every
        ACK_EVERY batches keeps that loss (and the memory queued behind the link) bounded.
        """
        stored = self._stored_next_seq()
        if self._base_seq is None:
            self._base_seq = stored if stored is not None else 0
            return
        while stored is not None and self._base_seq + self._sent - stored > MAX_IN_FLIGHT and not self.stop_requested():
            time.sleep(0.05)
            stored = self._stored_next_seq()

    def send_episode(self, record: wire.EpisodeRecord) -> None:
        self._episodes.put(wire.encode_episode(record))

    def latest_weights(self) -> bytes | None:
        return self._weights.take()

    def wait_weights(self, timeout: float) -> bytes | None:
        data = self._weights.wait(timeout)
        if data is None and time.monotonic() - self._last_query > 1.0:
            # Nothing pushed to us (we joined late, or reconnected): ask for the latest.
            self._last_query = time.monotonic()
            data = transport.query(self.session, wire.weights_latest_key(self.run_id), b"", self.timeout_s) or None
        if data is None:
            self._weights_wait.missed()
        else:
            self._weights_wait.answered()
        return data

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
