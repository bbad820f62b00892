"""Joining a running Ray cluster (``deploy/ray_connection.py``): through Ray Client (``ray://``)
the driver connects again when the head's client server for it failed to start, and only then.

Ray's ``init`` is replaced by a fake that fails as told, so nothing of Ray runs here (the real
case is tests/test_two_host.py's ``ray-client`` run).

Room: tests, unit. May import: laneshift.deploy, pytest and the standard library.
"""

from __future__ import annotations

import io

import pytest

from laneshift.deploy.ray_connection import CLIENT_SERVER_FAILED, CLIENT_TRIES, _join


class FakeInit:
    """``ray.init`` that raises ``errors`` in turn, then connects; records each call's address."""

    def __init__(self, *errors: Exception):
        self.errors, self.calls = list(errors), []

    def __call__(self, address: str, **kwargs) -> None:
        self.calls.append(address)
        if self.errors:
            raise self.errors.pop(0)


def failed_start() -> Exception:
    # What ray.init raises when the proxy could not start the driver's server (ray/util/client/worker.py).
    return ConnectionAbortedError("Initialization failure from server:\nTraceback ...\nRuntimeError: "
                                  f"{CLIENT_SERVER_FAILED}. See ray_client_server_23000.err for detailed logs.")


def test_ray_client_connects_again_when_the_heads_client_server_failed_to_start(monkeypatch):
    monkeypatch.setattr("time.sleep", lambda s: None)
    init, out = FakeInit(failed_start()), io.StringIO()
    _join(init, "ray://10.0.0.1:10001", out=out)
    assert init.calls == ["ray://10.0.0.1:10001"] * 2
    assert f"failed to start (try 1 of {CLIENT_TRIES}); connecting again" in out.getvalue()


def server_died_as_read() -> Exception:
    # The same death, seen by the proxy's psutil a moment later (CI, 2026-11-27): the traceback it sends.
    return ConnectionAbortedError(
        "Initialization failure from server:\nTraceback (most recent call last):\n"
        '  File ".../ray/util/client/server/proxier.py", line 767, in Datapath\n'
        "    if not self.proxy_manager.start_specific_server(\n"
        '  File ".../ray/util/client/server/proxier.py", line 396, in start_specific_server\n'
        "    cmd = psutil_proc.cmdline()\n"
        "psutil.ZombieProcess: PID still exists but it's a zombie (pid=27415)\n")


def test_ray_client_connects_again_when_the_heads_client_server_died_as_it_was_read(monkeypatch):
    monkeypatch.setattr("time.sleep", lambda s: None)
    init, out = FakeInit(server_died_as_read(), failed_start()), io.StringIO()
    _join(init, "ray://10.0.0.1:10001", out=out)
    assert init.calls == ["ray://10.0.0.1:10001"] * 3
    assert f"(try 2 of {CLIENT_TRIES}); connecting again" in out.getvalue()


def test_ray_client_gives_up_after_its_tries(monkeypatch):
    monkeypatch.setattr("time.sleep", lambda s: None)
    init = FakeInit(*[failed_start() for _ in range(CLIENT_TRIES)])
    with pytest.raises(ConnectionAbortedError, match=CLIENT_SERVER_FAILED):
        _join(init, "ray://10.0.0.1:10001", out=io.StringIO())
    assert len(init.calls) == CLIENT_TRIES


@pytest.mark.parametrize("address, error", [
    ("ray://10.0.0.1:10001", ConnectionError("ray client connection timeout")),  # another failure
    # psutil's error from somewhere other than the start of the driver's server
    ("ray://10.0.0.1:10001", ConnectionAbortedError("in get_node_info\npsutil.NoSuchProcess: process gone")),
    ("10.0.0.1:6379", RuntimeError(CLIENT_SERVER_FAILED)),  # not Ray Client: no client server to restart
])
def test_any_other_failure_is_raised_at_once(address, error):
    init = FakeInit(error)
    with pytest.raises(type(error)):
        _join(init, address, out=io.StringIO())
    assert len(init.calls) == 1
