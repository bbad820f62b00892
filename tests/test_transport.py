"""The zenoh transport contract every component relies on: a client behind a router, BLOCK
back-pressure instead of loss, no shared memory, and a publisher that can wait for its subscriber.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import json
import threading
import time

import zenoh

from laneshift import transport
from laneshift.config import TransportConfig


def test_session_config_is_client_behind_router_without_shared_memory() -> None:
    conf = json.loads(str(transport.session_config("tcp/127.0.0.1:7447", "client")))
    assert conf["mode"] == "client"
    assert conf["connect"]["endpoints"] == ["tcp/127.0.0.1:7447"] and conf["listen"]["endpoints"] == []
    assert conf["scouting"]["multicast"]["enabled"] is False and conf["scouting"]["gossip"]["enabled"] is False
    # Shared memory dropped messages under CPU starvation ("Buffer is invalidated"), BLOCK or not.
    assert conf["transport"]["shared_memory"]["enabled"] is False
    queue = conf["transport"]["link"]["tx"]["queue"]
    assert queue["size"]["data"] == 16 and queue["congestion_control"]["block"]["wait_before_close"] == 60_000_000
    assert queue["batching"]["enabled"] is True  # zenoh's default, kept for streams
    # The sample path's two ends send unbatched: a reply's last batch is not held back.
    unbatched = json.loads(str(transport.session_config("tcp/127.0.0.1:7447", "client", batching=False)))
    assert unbatched["transport"]["link"]["tx"]["queue"]["batching"]["enabled"] is False
    router = json.loads(str(transport.session_config("tcp/127.0.0.1:7447", "router")))
    assert router["listen"]["endpoints"] == ["tcp/127.0.0.1:7447"]
    assert router["transport"]["shared_memory"]["enabled"] is False


def test_slow_subscriber_gets_every_large_message_in_order() -> None:
    """22 KB messages (one actor batch) to a subscriber that drains slower than they are put:
    the publisher is held back (BLOCK), nothing is dropped or reordered."""
    cfg = TransportConfig(router=f"tcp/127.0.0.1:{transport.free_tcp_port()}", run_id="t")
    n, size = 600, 22_000
    with zenoh.open(transport.session_config(cfg.router, "router")), \
            transport.open_session(cfg) as sub_session, transport.open_session(cfg) as pub_session:
        sub = sub_session.declare_subscriber("t/data", zenoh.handlers.FifoChannel(8))
        pub = transport.data_publisher(pub_session, "t/data")
        assert transport.wait_matching(pub, 30), "the subscriber never became known to the publisher"
        got: list[int] = []

        def consume() -> None:
            for _ in range(n):
                got.append(int.from_bytes(sub.recv().payload.to_bytes()[:4], "little"))
                time.sleep(0.0005)  # a consumer slower than the producer

        consumer = threading.Thread(target=consume, daemon=True)
        consumer.start()
        for i in range(n):
            pub.put(i.to_bytes(4, "little") * (size // 4))
        consumer.join(30)
        assert not consumer.is_alive(), f"only {len(got)} of {n} messages arrived"
        assert got == list(range(n))
        assert sub.try_recv() is None


def test_requests_started_together_are_answered_together() -> None:
    """``Requester.start`` sends at once and waits only when called: two queryables that each take
    0.4 s to answer, asked one after the other without waiting, answer in about 0.4 s, not 0.8
    (``learner.shards.ShardedReplay`` asks its shards this way from one thread)."""
    cfg = TransportConfig(router=f"tcp/127.0.0.1:{transport.free_tcp_port()}", run_id="t")
    stop = threading.Event()

    def slow(name: bytes):
        def answer(payload: bytes) -> bytes:
            time.sleep(0.4)
            return name + payload
        return answer

    with zenoh.open(transport.session_config(cfg.router, "router")), \
            transport.open_session(cfg, batching=False) as server, \
            transport.open_session(cfg, batching=False) as client:
        transport.serve_queries(server, "t/a", slow(b"a:"), stop, "a")
        transport.serve_queries(server, "t/b", slow(b"b:"), stop, "b")
        ask_a, ask_b = transport.Requester(client, "t/a", 5.0), transport.Requester(client, "t/b", 5.0)
        assert transport.wait_for(lambda: ask_a(b"") is not None and ask_b(b"") is not None, 30)
        t0 = time.monotonic()
        pending = [ask_a.start(b"1"), ask_b.start(b"2")]
        replies = [wait() for wait in pending]
        took = time.monotonic() - t0
        stop.set()
    assert replies == [b"a:1", b"b:2"]
    assert took < 0.75, f"the two requests took {took:.2f} s: they did not overlap"
