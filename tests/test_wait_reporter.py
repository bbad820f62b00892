"""Every network wait says what it waits for, so a waiting process is never silent: one line
after a few seconds naming the endpoint or key, again at most every 30 s, and one when it is over.

What it is: transport.WaitReporter and wait_with_lines on a fake clock; an env worker's links waiting
for weights through a real router in this process; and a real `laneshift learner` started with no
router, which must say it waits for the router, then, once one is started, that it connected and
that it waits for the replay server.
Room: tests, unit. May import: the standard library, pytest, numpy, zenoh and laneshift.
Every process this file starts is ended by its own PID (SIGTERM, then SIGKILL after a bound).
"""

from __future__ import annotations

import contextlib
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from laneshift import transport, wire
from laneshift.actors.links import ZenohActorLinks
from laneshift.config import TransportConfig
from laneshift.deploy.processes import terminate

ROOT = Path(__file__).resolve().parents[1]


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def lines_on(clock: FakeClock, **kw) -> tuple[transport.WaitReporter, list[str]]:
    out: list[str] = []
    return transport.WaitReporter("learner", "the zenoh router at tcp/127.0.0.1:1 (transport.router)",
                               "connected to the zenoh router at tcp/127.0.0.1:1", clock=clock, emit=out.append,
                               **kw), out


# --------------------------------------------------------------------------- the helper, on a fake clock


def test_a_wait_is_said_after_a_few_seconds_then_every_30_s_then_once_when_over():
    clock = FakeClock()
    lines, out = lines_on(clock)
    for _ in range(200):  # 100 s of checks, one every 0.5 s
        lines.missed()
        clock.now += 0.5
    assert out == ["learner: waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router) ...",
                   "learner: still waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router), 35 s so far",
                   "learner: still waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router), 65 s so far",
                   "learner: still waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router), 95 s so far"]
    lines.answered()
    assert out[-1] == "learner: connected to the zenoh router at tcp/127.0.0.1:1 after 100.0 s"
    lines.answered()  # still there: nothing more
    assert len(out) == 5


def test_a_short_wait_says_nothing_and_a_flapping_one_no_more_than_one_line_per_30_s():
    clock = FakeClock()
    lines, out = lines_on(clock)
    for _ in range(3):  # 4.5 s of no answer, then an answer: quiet
        lines.missed()
        clock.now += 1.5
    lines.answered()
    assert out == []
    for _ in range(10):  # 10 waits of 6 s each, 2 s apart
        for _ in range(7):
            lines.missed()
            clock.now += 1.0
        lines.answered()
        clock.now += 2.0
    waiting = [line for line in out if "waiting" in line]
    assert len(waiting) == 3, out  # at 0, 32 and 64 s of the 80 s
    assert len(out) == 2 * len(waiting)  # each reported wait is also reported over


def test_quiet_lines_say_nothing():
    clock = FakeClock()
    lines, out = lines_on(clock, quiet=True)
    for _ in range(100):
        lines.missed()
        clock.now += 1.0
    lines.answered()
    assert out == []


def test_wait_with_lines_returns_at_once_when_ready_and_reports_a_long_wait():
    clock = FakeClock()
    lines, out = lines_on(clock)
    calls: list[float] = []
    assert transport.wait_with_lines(lines, lambda t: calls.append(t) or True)
    assert calls == [1.0] and out == []  # ready at the first call: no line, no waiting of its own

    def ready_after(at: float):
        def ready(t: float) -> bool:
            if clock.now + t >= at:
                clock.now = max(clock.now, at)
                return True
            clock.now += t
            return False
        return ready

    assert transport.wait_with_lines(lines, ready_after(clock.now + 42.3))
    assert out == ["learner: waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router) ...",
                   "learner: still waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router), 35 s so far",
                   "learner: connected to the zenoh router at tcp/127.0.0.1:1 after 42.3 s"]


def test_wait_with_lines_gives_up_at_its_timeout_or_stop():
    clock = FakeClock()
    lines, out = lines_on(clock)

    def never(t: float) -> bool:
        clock.now += t
        return False

    start = clock.now
    assert not transport.wait_with_lines(lines, never, timeout_s=7.5)
    assert clock.now - start == pytest.approx(7.5)
    assert out == ["learner: waiting for the zenoh router at tcp/127.0.0.1:1 (transport.router) ..."]
    stop = threading.Event()
    stop.set()
    assert not transport.wait_with_lines(lines, never, stop=stop)


# --------------------------------------------------------------------------- sessions and links, in this process


def test_open_session_with_a_router_there_says_nothing_and_names_its_router(capsys):
    cfg = TransportConfig(router=f"tcp/127.0.0.1:{transport.free_tcp_port()}", run_id="t")
    with zenoh.open(transport.session_config(cfg.router, "router")):
        started = time.monotonic()
        with transport.open_session(cfg, who="t") as session:
            assert time.monotonic() - started < 2.0
            assert transport.router_of(session) == cfg.router
    assert capsys.readouterr().err == ""


def test_open_session_says_it_waits_then_connected_and_stops_on_request(monkeypatch, capsys):
    monkeypatch.setattr(transport, "WAIT_FIRST_LINE_S", 0.5)
    cfg = TransportConfig(router=f"tcp/127.0.0.1:{transport.free_tcp_port()}", run_id="t")
    stop = threading.Event()
    result: dict[str, object] = {}

    def open_it() -> None:
        try:
            result["session"] = transport.open_session(cfg, who="w7", stop=stop)
        except InterruptedError as exc:
            result["error"] = exc

    opener = threading.Thread(target=open_it, daemon=True)
    opener.start()
    opener.join(3.0)
    assert opener.is_alive()
    stop.set()
    opener.join(5.0)
    assert not opener.is_alive() and str(result["error"]) == f"stopped while waiting for the zenoh router at {cfg.router}"
    err = capsys.readouterr().err
    assert err.splitlines() == [f"w7: waiting for the zenoh router at {cfg.router} (transport.router) ..."]

    opener = threading.Thread(target=open_it, daemon=True)
    opener.start()
    stop.clear()
    time.sleep(1.5)
    with zenoh.open(transport.session_config(cfg.router, "router")):
        opener.join(15.0)
        assert not opener.is_alive()
        result["session"].close()  # type: ignore[attr-defined]
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"w7: waiting for the zenoh router at {cfg.router} (transport.router) ..."
    assert err[-1].startswith(f"w7: connected to the zenoh router at {cfg.router} after "), err


@contextlib.contextmanager
def worker_links(monkeypatch, name: str):
    """A worker's links (run "t") through a router of their own, with the first line due at 0.5 s."""
    monkeypatch.setattr(transport, "WAIT_FIRST_LINE_S", 0.5)
    cfg = TransportConfig(router=f"tcp/127.0.0.1:{transport.free_tcp_port()}", run_id="t")
    with zenoh.open(transport.session_config(cfg.router, "router")), transport.open_session(cfg) as session:
        links = ZenohActorLinks(session, "t", name, timeout_s=0.5)
        try:
            yield cfg, session, links
        finally:
            links.close()


def test_a_worker_says_it_waits_for_weights_then_that_they_came(monkeypatch, capsys):
    with worker_links(monkeypatch, "w3") as (cfg, session, links):
        deadline = time.monotonic() + 10
        until = time.monotonic() + 1.5  # no learner: 1.5 s of unanswered waits (the first line is due at 0.5 s)
        while time.monotonic() < until:
            assert links.wait_weights(0.1) is None
        first = capsys.readouterr().err.splitlines()
        assert first == [f"w3: waiting for the learner's weights on {wire.weights_key('t')} "
                         f"(router {cfg.router}) ..."], first
        stop = threading.Event()
        weights = wire.encode_weights(wire.Weights(version=4, phase=0, updates=9,
                                                   tensors={"w": np.arange(3, dtype=np.float32)}))
        transport.serve_queries(session, wire.weights_latest_key("t"), lambda _: weights, stop)
        try:
            got = None
            while time.monotonic() < deadline and got is None:
                got = links.wait_weights(0.1)
            assert isinstance(got, wire.Weights) and (got.version, got.updates) == (4, 9)  # decoded by the links
            assert got.tensors["w"].tolist() == [0.0, 1.0, 2.0]
        finally:
            stop.set()
        last = capsys.readouterr().err.splitlines()
        assert len(last) == 1 and last[0].startswith("w3: got the learner's weights after "), last


def test_a_worker_says_it_waits_for_the_replay_server_and_its_flow_control(monkeypatch, capsys):
    with worker_links(monkeypatch, "w1") as (cfg, session, links):
        until = time.monotonic() + 1.5  # no replay server: its control key goes unanswered
        while time.monotonic() < until:
            assert links.stored_state() is None
            time.sleep(0.1)
        assert capsys.readouterr().err.splitlines() == [
            f"w1: waiting for the replay server on {wire.replay_control_key('t')} (router {cfg.router}) ..."]

        # The rate limiter says stop, then, 1.5 s later, go on.
        session.put(wire.replay_flow_key("t"), wire.encode_json({"insert_ok": False}))
        waiter = threading.Thread(target=links.wait_insert_ok, daemon=True)
        time.sleep(0.2)
        waiter.start()
        time.sleep(1.5)
        session.put(wire.replay_flow_key("t"), wire.encode_json({"insert_ok": True}))
        waiter.join(10)
        assert not waiter.is_alive()
        err = capsys.readouterr().err.splitlines()
        assert err[0] == (f"w1: waiting for the replay server to allow inserts on {wire.replay_flow_key('t')} "
                          f"(rate limiter; router {cfg.router}) ..."), err
        assert len(err) == 2 and err[1].startswith("w1: the replay server allows inserts again after "), err


# --------------------------------------------------------------------------- a real learner process


def start(argv: list[str]) -> tuple[subprocess.Popen, queue.Queue]:
    """A laneshift command as a subprocess; its output lines (stdout and stderr) come on the queue."""
    proc = subprocess.Popen([sys.executable, "-m", "laneshift", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)
    out: queue.Queue = queue.Queue()

    def read() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            out.put(line.rstrip("\n"))

    threading.Thread(target=read, daemon=True).start()
    return proc, out


def wait_line(out: queue.Queue, seen: list[str], starts: str, timeout_s: float) -> str:
    """The first line starting with ``starts`` (every line read is kept in ``seen``)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            line = out.get(timeout=max(0.01, deadline - time.monotonic()))
        except queue.Empty:
            break
        seen.append(line)
        if line.startswith(starts):
            return line
    pytest.fail(f"no line starting {starts!r} within {timeout_s} s; output so far:\n" + "\n".join(seen))


def learner_argv(endpoint: str, run_dir: Path) -> list[str]:
    return ["learner", "--set", f"transport.router={endpoint}", "--set", f"train.run_dir={run_dir}",
            "--set", "transport.run_id=waits", "--set", "learner.metrics_port=-1"]


def test_the_learner_says_it_waits_for_the_router_then_connected_then_waits_for_the_replay_server(tmp_path):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    procs: list[subprocess.Popen] = []
    seen: list[str] = []
    try:
        learner, out = start(learner_argv(endpoint, tmp_path / "run"))
        procs.append(learner)
        # The line is due 5 s into the wait: ~8 s after the start on an idle machine (imports take
        # 3 s); the bound leaves room for a loaded one (12 s to the line with load 6 on 2 cores).
        line = wait_line(out, seen, "learner: waiting for the zenoh router", 40)
        assert line == f"learner: waiting for the zenoh router at {endpoint} (transport.router) ...", line
        router, _ = start(["router", "--listen", endpoint])
        procs.insert(0, router)
        line = wait_line(out, seen, "learner: connected to the zenoh router", 30)
        assert line.startswith(f"learner: connected to the zenoh router at {endpoint} after "), line
        # No replay server on this run: the learner's sample queries go unanswered, and it says so.
        line = wait_line(out, seen, "learner: waiting for the replay server", 30)
        assert line == (f"learner: waiting for the replay server on {wire.sample_key('waits')} "
                        f"(router {endpoint}) ..."), line
        assert terminate(learner, 30) == 0, "\n".join(seen)
    finally:
        for proc in reversed(procs):  # the learner before its router
            terminate(proc, 10)


def test_a_learner_stopped_while_waiting_for_its_router_exits_at_once(tmp_path):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    seen: list[str] = []
    learner, out = start(learner_argv(endpoint, tmp_path / "run"))
    try:
        wait_line(out, seen, "learner: waiting for the zenoh router", 40)
        learner.send_signal(signal.SIGTERM)
        assert learner.wait(10) == 0
        line = wait_line(out, seen, "learner: stopped while waiting", 5)
        assert line == f"learner: stopped while waiting for the zenoh router at {endpoint}"
    finally:
        terminate(learner, 10)


def replay_server_argv(endpoint: str, run_dir: Path, *extra: str) -> list[str]:
    return ["replay-server", "--set", f"transport.router={endpoint}", "--set", f"train.run_dir={run_dir}",
            "--set", "transport.run_id=waits", "--set", "replay.demo_mode=none", "--set", "replay.http_port=-1",
            *extra]


@pytest.mark.parametrize("command", ["replay-server", "learner"])
def test_a_service_with_a_connect_timeout_gives_up_in_one_line_naming_its_router(tmp_path, command):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    argv = (replay_server_argv(endpoint, tmp_path / "run") if command == "replay-server"
            else learner_argv(endpoint, tmp_path / "run"))
    proc = subprocess.run([sys.executable, "-m", "laneshift", *argv, "--set", "transport.connect_timeout_s=2"],
                          cwd=ROOT, capture_output=True, text=True, timeout=90, stdin=subprocess.DEVNULL)
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert f"{command}: no zenoh router answered at {endpoint} within 2 s" in proc.stderr, proc.stderr


def test_a_replay_server_stopped_while_waiting_for_its_router_exits_0_in_one_line(tmp_path):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    seen: list[str] = []
    server, out = start(replay_server_argv(endpoint, tmp_path / "run"))
    try:
        line = wait_line(out, seen, "replay-server: waiting for the zenoh router", 40)
        assert line == f"replay-server: waiting for the zenoh router at {endpoint} (transport.router) ...", line
        server.send_signal(signal.SIGTERM)
        assert server.wait(10) == 0, "\n".join(seen)
        line = wait_line(out, seen, "replay-server: stopped while waiting", 5)
        assert line == f"replay-server: stopped while waiting for the zenoh router at {endpoint}"
        assert not any("Traceback" in s for s in seen), "\n".join(seen)
    finally:
        terminate(server, 10)
