"""The worker's seams over zenoh: transitions out (BLOCK), newest weights in, control in.

    >>> links = ZenohActorLinks(session, "run", "w0")  # doctest: +SKIP
    >>> worker.run(links, env_steps=10_000)  # doctest: +SKIP
"""

from __future__ import annotations

import time

import zenoh

from laneshift import transport, wire


class ZenohActorLinks:
    def __init__(self, session: zenoh.Session, run_id: str, name: str, timeout_s: float = 5.0):
        self.session, self.run_id, self.timeout_s = session, run_id, timeout_s
        self._transitions = transport.data_publisher(session, wire.transitions_key(run_id, name))
        self._episodes = transport.data_publisher(session, wire.episodes_key(run_id, name))
        self._weights = transport.LatestValue(session, wire.weights_key(run_id))
        self._stop = transport.StopSignal(session, wire.control_key(run_id))
        self._flow = transport.LatestValue(session, wire.replay_flow_key(run_id))
        self._insert_ok = True
        self._last_query = 0.0
        self._first_send = True

    def send_transitions(self, payload: bytes) -> None:
        if self._first_send:
            # First batch only: wait for the replay server's subscription to reach this session.
            # If it never does, send anyway (the server counts the gap in seq as lost batches)
            # and do not wait again: the hot path must not pay timeout_s per batch.
            self._first_send = False
            transport.wait_matching(self._transitions, self.timeout_s)
        self._transitions.put(payload)

    def send_episode(self, payload: bytes) -> None:
        self._episodes.put(payload)

    def latest_weights(self) -> bytes | None:
        return self._weights.take()

    def wait_weights(self, timeout: float) -> bytes | None:
        data = self._weights.wait(timeout)
        if data is None and time.monotonic() - self._last_query > 1.0:
            # Nothing pushed to us (we joined late, or reconnected): ask for the latest.
            self._last_query = time.monotonic()
            data = transport.query(self.session, wire.weights_latest_key(self.run_id), b"", self.timeout_s) or None
        return data

    def wait_insert_ok(self) -> None:
        """Block while the replay server says the learner is too far behind (rate limiter)."""
        self._update_flow(self._flow.take())
        while not self._insert_ok and not self.stop_requested():
            self._update_flow(self._flow.wait(0.5))

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
