"""The replay server's HTTP JSON inspection API (read-only), served inside the replay-server process.

``make_app(core)`` builds a FastAPI app over a live :class:`ReplayCore`; ``serve_http`` runs it
with uvicorn in a daemon thread. Endpoints (details and example responses in docs/replay-api.md):

- ``GET /healthz``: liveness (503 when the core's lock cannot be had within 2 s);
- ``GET /stats``: ``core.stats()`` with each table's view added under ``tables.<name>``;
- ``GET /tables/{online|demo}/items?offset=&limit=&include_obs=``: decoded transitions, paged
  from the oldest item; rows are copied out under the core's lock, so every item is whole even
  while actors insert;
- ``GET /demo``: the demo shard's metadata, sha256 and sizes;
- ``GET /info``: what ``replay/info`` answers over zenoh (observation shape and dtype, action count);
- ``GET /metrics``: Prometheus text exposition format 0.0.4, names prefixed ``laneshift_replay_``, plus
  the process's ``process_*`` metrics;
- ``GET /openapi.json`` and ``GET /docs``: the schema FastAPI generates.

Nothing here writes to the core. Endpoints are plain ``def`` functions: FastAPI runs them in its
worker threads, so waiting for the core's lock never blocks the event loop.

The pieces: ``views`` (what is read from the core), ``http_models`` (the JSON and the documented
shapes), ``prometheus`` (``/metrics`` with prometheus_client); this module is the app and its
thread server.

Room: replay_server (component). May import: the replay core and the modules above, fastapi, uvicorn,
prometheus_client, numpy; never ``.service`` (which imports this module to serve it) and nothing
that writes to the core.

    >>> from laneshift.config import ReplayConfig
    >>> from laneshift.wire import TransitionSchema
    >>> core = ReplayCore(ReplayConfig(capacity=100, min_size=10), TransitionSchema((3,), "float32", 9))
    >>> read_items(core, "online", offset=0, limit=10, include_obs=False)["total"]
    0
    >>> sorted(r.path for r in make_app(core).routes if r.path.startswith(("/t", "/s")))
    ['/stats', '/tables/{name}/items']
"""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time

import uvicorn
from fastapi import FastAPI, HTTPException, Query
from fastapi.responses import Response
from prometheus_client import generate_latest

from .core import MAX_ACTOR_PAGE, ReplayCore

from .http_models import DEFAULT_LIMIT, MAX_LIMIT, TABLES, Health, Info, ItemsPage, Problem, SafeJSONResponse
from .prometheus import PROMETHEUS_CONTENT_TYPE, metrics_registry
from .views import demo_info, full_stats, read_items  # noqa: F401 - read_items: the doctest above

HEALTH_LOCK_TIMEOUT_S = 2.0


# --------------------------------------------------------------------------- the app


def make_app(core: ReplayCore) -> FastAPI:
    app = FastAPI(title="laneshift replay server", version="1",
                  description="Read-only inspection of a running replay server: stats, stored transitions, "
                              "the demo shard, Prometheus metrics. See docs/replay-api.md.",
                  default_response_class=SafeJSONResponse)
    app.state.core = core

    @app.get("/healthz", response_model=None, responses={200: {"model": Health}, 503: {"model": Health}})
    def healthz() -> Response:
        """Liveness: answers once the core's lock can be taken (503 if not within 2 s)."""
        got = core.lock.acquire(timeout=HEALTH_LOCK_TIMEOUT_S)
        try:
            body = {"status": "ok" if got else "unavailable", "mode": core.mode, "phase": core.phase,
                    "uptime_s": round(time.monotonic() - core.started, 3),
                    "online_size": core.online.size}
        finally:
            if got:
                core.lock.release()
        return SafeJSONResponse(body, status_code=200 if got else 503)

    @app.get("/stats", response_model=None)
    def stats() -> Response:
        """Everything ``core.stats()`` reports, with each table's view under ``tables.online`` and
        ``tables.demo``: size, capacity, inserts_per_s, samples_per_s, sampled_rows, share_buffer,
        share_recent_samples; online also items_per_actor, rate_limiter, checkpoint_age_s; demo sha256."""
        return SafeJSONResponse(full_stats(core))

    @app.get("/tables/{name}/items", response_model=None,
             responses={200: {"model": ItemsPage}, 404: {"model": Problem}, 422: {"model": Problem}})
    def items(name: str,
              offset: int = Query(0, ge=0, description="items to skip, counted from the oldest item"),
              limit: int = Query(DEFAULT_LIMIT, ge=1, description=f"items to return; more than {MAX_LIMIT} "
                                                                  f"returns {MAX_LIMIT}"),
              include_obs: bool = Query(False, description="include obs and next_obs (large for images)")
              ) -> Response:
        """Decoded transitions of table ``online`` or ``demo``, oldest first."""
        if name not in TABLES:
            raise HTTPException(404, f"unknown table {name!r}; tables: {', '.join(TABLES)}")
        return SafeJSONResponse(read_items(core, name, offset, min(limit, MAX_LIMIT), include_obs))

    @app.get("/actors", response_model=None)
    def actors(offset: int = Query(0, ge=0, description="actors to skip, in name order"),
               limit: int = Query(MAX_ACTOR_PAGE, ge=1, description=f"actors to return (at most {MAX_ACTOR_PAGE})")
               ) -> Response:
        """Per-actor counters, a page at a time: ``{"total", "offset", "actors": {name: {...}}}``."""
        return SafeJSONResponse(core.actor_page(offset, limit))

    @app.get("/demo", response_model=None)
    def demo() -> Response:
        """The demo shard: metadata (as recorded), sha256, items and bytes loaded and in the buffer."""
        return SafeJSONResponse(demo_info(core))

    @app.get("/info", response_model=None, responses={200: {"model": Info}})
    def info() -> Response:
        """What ``replay/info`` answers over zenoh: the wire version, observation shape and dtype,
        action count, run id, demo mode and this API's URL."""
        return SafeJSONResponse(core.info(core.identity.get("run_id")))

    registry = metrics_registry(core)

    @app.get("/metrics", response_class=Response, responses={200: {"content": {PROMETHEUS_CONTENT_TYPE: {}}}})
    def metrics() -> Response:
        """Prometheus text exposition format 0.0.4 (prometheus_client's ``generate_latest``)."""
        return Response(generate_latest(registry), media_type=PROMETHEUS_CONTENT_TYPE)

    return app


# --------------------------------------------------------------------------- serving


class _ThreadServer(uvicorn.Server):
    """uvicorn that leaves the process's signal handlers alone and stops when ``stop`` is set."""

    def __init__(self, config: uvicorn.Config, stop: threading.Event):
        super().__init__(config)
        self._stop = stop

    def install_signal_handlers(self) -> None:  # uvicorn < 0.29
        pass

    @contextlib.contextmanager
    def capture_signals(self):  # uvicorn >= 0.29
        yield

    async def on_tick(self, counter: int) -> bool:
        if self._stop.is_set():
            return True
        return await super().on_tick(counter)


def _bind(host: str, port: int) -> socket.socket:
    family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                                      flags=socket.AI_PASSIVE)[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(addr)
        sock.listen(128)
    except OSError:
        sock.close()
        raise
    return sock


def serve_http(core: ReplayCore, host: str = "127.0.0.1", port: int = 0, stop: threading.Event | None = None,
               *, startup_timeout_s: float = 10.0) -> tuple[threading.Thread, int]:
    """Serve ``make_app(core)`` on ``host:port`` from a daemon thread; returns (thread, bound port).

    ``port=0`` picks a free port. The socket is bound before this returns (an address in use
    raises OSError here) and the server is accepting connections. Setting ``stop`` shuts it down
    within about 0.1 s plus the time open requests need (at most 2 s); the thread then ends.
    Without ``stop`` an Event is made and left on ``thread.stop_event``.
    """
    stop = stop if stop is not None else threading.Event()
    sock = _bind(host, port)
    bound = sock.getsockname()[1]
    config = uvicorn.Config(make_app(core), log_level="warning", log_config=None, access_log=False,
                            lifespan="off", timeout_graceful_shutdown=2, server_header=False)
    server = _ThreadServer(config, stop)
    failure: list[BaseException] = []

    def run() -> None:
        try:
            server.run(sockets=[sock])
        except BaseException as exc:  # noqa: BLE001 - reported to serve_http's caller, or to stderr
            failure.append(exc)
            if server.started:
                raise
        finally:
            sock.close()

    thread = threading.Thread(target=run, name=f"replay-http-{bound}", daemon=True)
    thread.stop_event = stop  # type: ignore[attr-defined]
    thread.server = server  # type: ignore[attr-defined]
    thread.start()
    waited = 0.0
    while not server.started:
        if failure or not thread.is_alive():
            raise RuntimeError(f"replay HTTP API on {host}:{bound} failed to start: "
                               f"{failure[0] if failure else 'server thread ended'}")
        if waited >= startup_timeout_s:
            stop.set()
            raise RuntimeError(f"replay HTTP API on {host}:{bound} did not start within {startup_timeout_s} s")
        thread.join(0.01)
        waited += 0.01
    return thread, bound
