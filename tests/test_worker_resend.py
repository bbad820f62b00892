"""A worker's resend against a real replay server process: the batches it sent that the server
does not hold (killed with -9 while they were on their way, or dropped by a connection reset) are
sent again from the worker's own buffer, with the same seq, so the server ends with every batch
once: made == stored, 0 lost, and the copies it already had are ignored and counted as duplicates.

Also when the worker ends early or waits: a worker stopped gracefully (the run's stop message)
sends again, within a bounded flush, what the server lacks, and reports what it could not deliver;
a sync-mode worker waiting for its round's weights sends again a batch lost on its way (that
round waited for it for ever). A lost put is made by ``DropOnce``, the worker's real publisher
with one batch's put left out.

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
from laneshift.actors.links import MAX_IN_FLIGHT, RESEND_AFTER_S, STOP_FLUSH_S, ZenohActorLinks
from laneshift.actors.seams import Delivery
from laneshift.config import TransportConfig, load_run_config, save_run_config
from laneshift.deploy.builder import Builder
from laneshift.deploy.linkproxy import LinkProxy
from laneshift.deploy.processes import ProcessGroup, wait_for_file
from laneshift.qnet import build_q_network, to_wire

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
            assert not sender.is_alive() and sender.flushed == Delivery()
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
                assert not sender.is_alive() and sender.flushed == Delivery()
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
            assert sender.flushed == Delivery() and not links._unacked
            assert_every_batch_once(server.stats(session))
            links.close()
    finally:
        server.group.stop_all()


class DropOnce:
    """A worker's transitions publisher whose put of batch ``seq`` (its first put: not a resend)
    goes nowhere: a batch lost on its way, with nothing after it on the link to show it."""

    def __init__(self, links: ZenohActorLinks, seq: int):
        self.publisher, self.seq, self.dropped = links._transitions, seq, False
        links._transitions = self

    @property
    def matching_status(self):
        return self.publisher.matching_status

    def put(self, payload: bytes) -> None:
        if not self.dropped and wire.decode(payload).header["seq"] == self.seq:
            self.dropped = True
            return
        self.publisher.put(payload)


def stop_run(session, run_id: str) -> None:
    """The run's stop message, as the launcher's graceful end broadcasts it."""
    session.put(wire.control_key(run_id), wire.encode_json({"cmd": "stop"}))


@pytest.mark.parametrize("dropped", [5, 7], ids=["a-gap", "the-newest"])
def test_a_stopped_worker_sends_again_what_the_server_lacks_before_it_ends(tmp_path, dropped):
    """Eight batches, one lost on its way (a gap before the newest, or the newest itself, which
    nothing after it shows), then the stop: the flush sends it again within STOP_FLUSH_S, and
    the server ends with every batch once (the flush used to end at once on a stop)."""
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0})
    cfg = TransportConfig(router=server.endpoint, run_id=server.cfg.transport.run_id)
    try:
        with transport.open_session(cfg) as session:
            links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=2.0)
            drop = DropOnce(links, dropped)
            for seq in range(8):
                links.send_transitions(batch(seq))
            assert drop.dropped
            stop_run(session, cfg.run_id)
            assert transport.wait_for(links.stop_requested, 10)
            started = time.monotonic()
            delivery = links.flush()
            took = time.monotonic() - started
            assert delivery == Delivery() and not links._unacked, delivery
            assert took <= STOP_FLUSH_S + 0.5, took
            assert links.resent >= 1
            w0 = server.stats(session)["actors"]["w0"]
            assert (w0["last_seq"], w0["stored"], w0["lost_batches"], w0["lost_items"]) == (7, 8 * ITEMS, 0, 0), w0
            links.close()
    finally:
        server.group.stop_all()


class WeightsFeed:
    """The learner's side of a worker test: one network's weights, published as version after
    version on the weights key and served to the worker's query for the latest."""

    def __init__(self, session, run_id: str, net):
        self.net, self.latest, self.stop = net, b"", threading.Event()
        self.pub = transport.data_publisher(session, wire.weights_key(run_id))
        transport.serve_queries(session, wire.weights_latest_key(run_id), lambda _: self.latest, self.stop)

    def publish(self, version: int) -> None:
        self.latest = to_wire(self.net, version, 0, version)
        self.pub.put(self.latest)


def _worker(server: Server, session) -> tuple:
    """The run's env worker w0 (LKA, as the server's config says) and a learner's weights over
    ``session`` for its network."""
    builder = Builder(server.cfg)
    schema = builder.spec.schema
    learner = WeightsFeed(session, server.cfg.transport.run_id,
                          build_q_network(schema.obs_shape, schema.n_actions, server.cfg.learner.hidden))
    return builder.env_worker(0), learner


class Run(threading.Thread):
    """``worker.run(links, env_steps)`` on a thread of its own; ``summary`` when it returned."""

    def __init__(self, worker, links: ZenohActorLinks, env_steps: int):
        super().__init__(daemon=True)
        self.worker, self.links, self.env_steps, self.summary = worker, links, env_steps, None

    def run(self) -> None:
        self.summary = self.worker.run(self.links, self.env_steps)


def test_a_sync_worker_waiting_for_its_rounds_weights_sends_a_lost_batch_again(tmp_path):
    """Sync mode: the learner publishes version v + 1 once the server holds the worker's batch of
    version v. Batch 1 is lost on its way: the worker, waiting for version 2, asks the server
    and sends it again, so the round goes on (the next ask was due 16 batches later, which a
    sync worker never sends while it waits: the run stalled)."""
    rounds, per_batch = 5, 16
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0, "train.parallel": "sync", "actor.workers": 1,
                                 "actor.envs_per_worker": 1, "actor.send_every": per_batch, "learner.hidden": "16"})
    cfg = TransportConfig(router=server.endpoint, run_id=server.cfg.transport.run_id)
    try:
        with transport.open_session(cfg) as session, transport.open_session(cfg) as theirs:
            worker, learner = _worker(server, theirs)
            links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=2.0)
            drop = DropOnce(links, 1)
            run = Run(worker, links, rounds * per_batch)
            run.start()
            waits = []
            for version in range(rounds):
                learner.publish(version)
                started = time.monotonic()
                # The learner's round: until the server holds the worker's batch of this version.
                held = transport.wait_for(lambda: server.stats(theirs).get("actors", {}).get("w0", {}).get(
                    "last_seq", -1) >= version, 30)
                assert held, f"round {version}: the server never got the worker's batch (the run stalls)"
                waits.append(time.monotonic() - started)
            run.join(60)
            assert not run.is_alive() and drop.dropped
            assert waits[1] <= RESEND_AFTER_S + 5.0, waits  # the lost batch came again within seconds
            assert links.resent >= 1
            summary = run.summary.as_dict()
            assert summary["version_runs"] == [[v, 1] for v in range(rounds)]
            assert (summary["undelivered_batches"], summary["undelivered_items"]) == (0, 0)
            w0 = server.stats(theirs)["actors"]["w0"]
            assert (w0["last_seq"], w0["stored"], w0["lost_batches"]) == (rounds - 1, rounds * per_batch, 0), w0
            learner.stop.set()
            links.close()
            worker.close()
    finally:
        server.group.stop_all()


def test_a_stopped_worker_whose_server_does_not_answer_ends_in_seconds_and_counts_what_it_could_not_deliver(
        tmp_path, capsys):
    """The replay server stops answering (SIGSTOP) while an async worker sends; then the run is
    stopped. The worker sends the batch it was filling, waits at most STOP_FLUSH_S for the server
    (plus one query's timeout if a query was under way), and its summary and log say how many
    batches and items the server did not confirm: lost, counted, never silent."""
    server = Server(tmp_path, **{"replay.checkpoint_every_s": 0, "replay.samples_per_insert": 0, "actor.workers": 1,
                                 "actor.envs_per_worker": 1, "actor.send_every": 16, "learner.hidden": "16"})
    cfg = TransportConfig(router=server.endpoint, run_id=server.cfg.transport.run_id)
    try:
        with transport.open_session(cfg) as session, transport.open_session(cfg) as theirs:
            worker, learner = _worker(server, theirs)
            links = ZenohActorLinks(session, cfg.run_id, "w0", timeout_s=1.0)
            learner.publish(0)
            run = Run(worker, links, 10_000_000)
            run.start()
            assert transport.wait_for(lambda: server.stats(theirs).get("actors", {}).get("w0", {}).get(
                "last_seq", -1) >= 2, 60)
            os.kill(server.pid, signal.SIGSTOP)
            sent = links._next_seq
            assert transport.wait_for(lambda: links._next_seq >= sent + 2, 30)  # on their way to no one
            stop_run(theirs, cfg.run_id)
            started = time.monotonic()
            run.join(30)
            took = time.monotonic() - started
            assert not run.is_alive()
            assert took <= STOP_FLUSH_S + 1.0 + 2.0, took  # the flush, a query under way (1 s), the last pass
            summary = run.summary.as_dict()
            assert summary["batches"] == links._next_seq
            assert 2 <= summary["undelivered_batches"] == len(links._unacked), summary
            assert summary["undelivered_items"] == sum(items for _, items in links._unacked.values()) > 0
            said = capsys.readouterr().out
            assert (f"w0: {summary['undelivered_batches']} batches ({summary['undelivered_items']} items) sent and "
                    f"not confirmed by the replay server when this worker ended: counted lost") in said
            os.kill(server.pid, signal.SIGCONT)
            learner.stop.set()
            links.close()
            worker.close()
    finally:
        server.group.stop_all()
