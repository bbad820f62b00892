"""A worker's resend against a real replay server process: the batches it sent that the server
does not hold (killed with -9 while they were on their way, or dropped by a connection reset) are
sent again from the worker's own buffer, with the same seq, so the server ends with every batch
once: made == stored, 0 lost, and the copies it already had are ignored and counted as duplicates.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from laneshift import transport, wire
from laneshift.actors.links import MAX_IN_FLIGHT, ZenohActorLinks
from laneshift.config import TransportConfig, load_run_config, save_run_config
from laneshift.deploy.linkproxy import LinkProxy
from laneshift.deploy.processes import ProcessGroup, wait_for_file

ITEMS = 10  # per batch
BATCHES = 240


def batch(seq: int) -> wire.TransitionBatch:
    """Batch ``seq`` of actor w0: items numbered seq * ITEMS.., env steps counted on."""
    k = np.arange(seq * ITEMS, (seq + 1) * ITEMS)
    obs = np.repeat(k[:, None], 6, axis=1).astype(np.float32)
    return wire.TransitionBatch.from_arrays(
        actor="w0", seq=seq, weights_version=0, phase=0, env_steps=(seq + 1) * ITEMS, obs=obs, action=k % 31,
        reward=k.astype(np.float32), next_obs=obs + 1, terminated=np.zeros(ITEMS), truncated=np.zeros(ITEMS))


class Server:
    """A router and a replay server (LKA's schema, write-ahead log on), as processes."""

    def __init__(self, tmp_path: Path, **overrides):
        self.endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
        self.cfg = load_run_config(overrides={"env.scenario": "lka", "transport.router": self.endpoint,
                                              "train.run_dir": str(tmp_path), "replay.capacity": 10_000,
                                              "replay.min_size": 1, **overrides})
        path = save_run_config(self.cfg, tmp_path / "config.yaml")
        self.ready = tmp_path / "ready"
        self.group = ProcessGroup(tmp_path / "logs")
        py = [sys.executable, "-m", "laneshift"]
        self.argv = [*py, "replay-server", "--config", str(path), "--ready-file", str(self.ready)]
        self.group.start("router", [*py, "router", "--listen", self.endpoint])
        self.start()

    def start(self) -> None:
        self.ready.unlink(missing_ok=True)
        self.group.start("replay-server", self.argv)
        wait_for_file(self.ready, 60, self.group, "replay-server")

    @property
    def pid(self) -> int:
        return self.group.procs["replay-server"].pid

    def kill_9(self) -> None:
        os.kill(self.pid, signal.SIGKILL)
        self.group.procs["replay-server"].wait(10)

    def stats(self, session) -> dict:
        reply = transport.query(session, wire.replay_stats_key(self.cfg.transport.run_id), b"", 5.0)
        return wire.decode_json(reply) if reply else {}


class Sender(threading.Thread):
    """A worker's sending side: BATCHES batches through ``links``, a few ms apart, then its flush."""

    def __init__(self, links: ZenohActorLinks):
        super().__init__(daemon=True)
        self.links, self.sent, self.flushed = links, 0, None

    def run(self) -> None:
        for seq in range(BATCHES):
            self.links.send_transitions(batch(seq))
            self.sent = seq + 1
            time.sleep(0.004)
        self.flushed = self.links.flush(timeout_s=90)

    def wait_sent(self, n: int, timeout_s: float = 60) -> None:
        assert transport.wait_for(lambda: self.sent >= n, timeout_s), (self.sent, n)


def assert_every_batch_once(stats: dict) -> dict:
    """made == stored, 0 lost: the table holds each of the BATCHES batches exactly once."""
    w0 = stats["actors"]["w0"]
    assert w0["last_seq"] == BATCHES - 1 and w0["env_steps"] == BATCHES * ITEMS, w0
    assert (w0["stored"], w0["lost_batches"], w0["lost_items"]) == (BATCHES * ITEMS, 0, 0), w0
    assert stats["tables"]["online"]["inserted"] == BATCHES * ITEMS, stats["tables"]
    assert stats["rejected"] == {}, stats["rejected"]
    return w0


@pytest.mark.parametrize("at", [0.1, 0.5, 0.9])
def test_a_replay_server_killed_with_batches_on_their_way_loses_none_of_them(tmp_path, at):
    """The server is stopped (SIGSTOP), so that batches the worker sends pile up on their way to
    it, then killed with -9 and started again: its log brings back what it took, the worker's
    buffer what it did not."""
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0.5})
    cfg = TransportConfig(router=server.endpoint, run_id=server.cfg.transport.run_id)
    try:
        with transport.open_session(cfg) as session:
            links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=2.0)
            sender = Sender(links)
            sender.start()
            sender.wait_sent(int(at * BATCHES))
            os.kill(server.pid, signal.SIGSTOP)
            stopped_at = sender.sent
            # A few more on their way to the stopped server (fewer than the window: the worker
            # blocks at MAX_IN_FLIGHT unacknowledged, and this one sends at most BATCHES).
            sender.wait_sent(min(BATCHES, stopped_at + 8))
            server.kill_9()
            server.start()
            sender.join(120)
            assert not sender.is_alive() and sender.flushed is True
            assert links.resent >= 1  # what died with the server came again from the worker
            stats = server.stats(session)
            assert_every_batch_once(stats)
            assert links.stored_state() == {"env_steps": BATCHES * ITEMS, "next_seq": BATCHES}
            links.close()
    finally:
        server.group.stop_all()


def test_connection_resets_lose_no_batch(tmp_path):
    """The worker reaches the router through a proxy that resets its connection three times while
    it sends: the puts that die with a connection are sent again, nothing is lost or stored twice."""
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0})
    port = int(server.endpoint.rsplit(":", 1)[1])
    with LinkProxy(port, latency_s=0.0, jitter_s=0.0, reset_every_s=0) as proxy:
        cfg = TransportConfig(router=proxy.endpoint, run_id=server.cfg.transport.run_id)
        try:
            with transport.open_session(cfg) as session:
                links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=2.0)
                sender = Sender(links)
                sender.start()
                for at in (0.2, 0.45, 0.7):
                    sender.wait_sent(int(at * BATCHES))
                    assert transport.wait_for(lambda: bool(proxy.live()), 30)  # reconnected since the last one
                    assert proxy.reset_one() is not None
                sender.join(120)
                assert not sender.is_alive() and sender.flushed is True
                assert proxy.stats.resets == 3
                with transport.open_session(TransportConfig(router=server.endpoint, run_id=cfg.run_id)) as direct:
                    assert_every_batch_once(server.stats(direct))
                links.close()
        finally:
            server.group.stop_all()


def test_the_worker_holds_at_most_its_window(tmp_path):
    """With no replay server answering, the worker stops at MAX_IN_FLIGHT unacknowledged batches
    (their bytes are what it keeps), and goes on once one answers."""
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0})
    cfg = TransportConfig(router=server.endpoint, run_id=server.cfg.transport.run_id)
    try:
        with transport.open_session(cfg) as session:
            links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=0.5)
            sender = Sender(links)
            sender.start()
            sender.wait_sent(20)
            os.kill(server.pid, signal.SIGSTOP)
            stopped_at = sender.sent
            sender.wait_sent(stopped_at + 1)
            time.sleep(3.0)  # long enough to send far more than the window
            assert sender.sent <= stopped_at + MAX_IN_FLIGHT and len(links._unacked) <= MAX_IN_FLIGHT
            assert sender.sent < BATCHES
            os.kill(server.pid, signal.SIGCONT)
            sender.join(120)
            assert sender.flushed is True and not links._unacked
            assert_every_batch_once(server.stats(session))
            links.close()
    finally:
        server.group.stop_all()
