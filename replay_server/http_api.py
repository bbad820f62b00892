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

``/metrics`` is built with prometheus_client (metric families read from ``full_stats()`` at scrape
time, on a registry of the app's own) rather than a hand-written text renderer: it does the format's
escaping, ``_total`` suffixes and histogram buckets, and brings the ``process_*`` collector, so this
module only says which numbers are which metrics.

May import: the replay core (and, for ``/info``, ``.service``), fastapi, uvicorn, prometheus_client,
numpy; nothing that writes to the core.

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
import math
import socket
import threading
import time
from typing import Any

import numpy as np
import uvicorn
from fastapi import FastAPI, HTTPException, Query
from fastapi.responses import JSONResponse, Response
from prometheus_client import CollectorRegistry, ProcessCollector, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily
from pydantic import BaseModel, Field

from .core import MAX_ACTOR_PAGE, ReplayCore

TABLES = ("online", "demo")
DEFAULT_LIMIT = 10
MAX_LIMIT = 100
HEALTH_LOCK_TIMEOUT_S = 2.0
PROMETHEUS_CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


# --------------------------------------------------------------------------- JSON


def _np_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")


def _finite(obj: Any) -> Any:
    """``obj`` with numpy values made plain and NaN / inf replaced by None (JSON has neither)."""
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (np.generic, np.ndarray)):
        return _finite(_np_default(obj))
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


class SafeJSONResponse(JSONResponse):
    """JSON that never fails on numpy values or non-finite floats (those become null)."""

    def render(self, content: Any) -> bytes:
        try:
            text = json.dumps(content, allow_nan=False, default=_np_default, separators=(",", ":"))
        except ValueError:  # a NaN or inf somewhere (e.g. in shard metadata): the slow path
            text = json.dumps(_finite(content), allow_nan=False, separators=(",", ":"))
        return text.encode("utf-8")


SHORT_FLOATS_MAX = 200_000  # numbers per page up to which float32 obs are written in their shortest form


def _obs_lists(arr: np.ndarray) -> list:
    """Rows of ``arr`` as nested lists; float32 / float16 in their shortest decimal form (0.2, not
    0.20000000298023224) when the page is small enough for that (numpy's shortest repr is ~1 us a number)."""
    if arr.dtype.kind == "f" and arr.dtype.itemsize < 8 and arr.size <= SHORT_FLOATS_MAX:
        arr = arr.astype(str).astype(np.float64)  # shortest repr, parses back to the same float32 bits
    return arr.tolist()


def _f32(x: Any) -> float:
    """A float32 as its shortest decimal (0.1, not 0.10000000149011612); parses back bit-exact."""
    return float(str(np.float32(x)))


# --------------------------------------------------------------------------- documented shapes (OpenAPI only)


class Health(BaseModel):
    status: str = Field(description="ok, or unavailable (503) when the core's lock was not free within 2 s")
    mode: str
    phase: int
    uptime_s: float
    online_size: int


class Item(BaseModel):
    key: int = Field(description="online: the item's global insertion key; demo: its row in the demo table "
                                 "(the index a sampled batch reports for demo rows)")
    action: int
    reward: float = Field(description="the discounted sum of `steps` rewards (1 = an ordinary transition)")
    steps: int = Field(description="rewards summed in `reward`; the learner bootstraps with gamma ** steps")
    terminated: bool
    truncated: bool | None = Field(None, description="online only")
    actor: str | None = Field(None, description="online only: the actor that sent the item")
    weights_version: int | None = Field(None, description="online only: the weights version that acted")
    priority: float | None = Field(None, description="prioritized sampler only: the item's sampling mass "
                                                    "(priority ** alpha; 0 = not sampled)")
    obs: list | None = Field(None, description="only with include_obs=true")
    next_obs: list | None = Field(None, description="only with include_obs=true")


class ItemsPage(BaseModel):
    table: str
    offset: int
    limit: int = Field(description="the limit applied (the one asked for, at most 100)")
    total: int = Field(description="items in the table when the page was read")
    oldest_key: int | None
    newest_key: int | None
    next_offset: int | None = Field(description="offset of the next page, null on the last one")
    include_obs: bool
    obs_shape: list[int]
    obs_dtype: str
    items: list[Item]


class Problem(BaseModel):
    detail: Any


class Info(BaseModel):
    wire_version: int = Field(description="the wire version this server speaks (docs/wire.md)")
    obs_shape: list[int] = Field(description="shape of one observation: TRANSITIONS carry obs [B, *obs_shape]")
    obs_dtype: str = Field(description="numpy little-endian code of obs and next_obs, e.g. <f4 or |u1")
    n_actions: int = Field(description="actions are integers in [0, n_actions)")
    run_id: str | None = Field(description="transport.run_id: keys are laneshift/<run_id>/...")
    mode: str = Field(description="replay.demo_mode")
    http_url: str | None = Field(description="this API's address as the server announces it, null if off")


# --------------------------------------------------------------------------- reading the core


def _table_views(core: ReplayCore, stats: dict) -> dict[str, dict]:
    """What the issue asks per table, computed from ``stats`` plus the online table's actor column."""
    with core._lock:
        size = core.online.size
        actor_rows = core.online.actor[:size].copy()  # rows of live items: keys are contiguous
        names = {i: name for name, i in core._actor_index.items()}
        demo_region = core.demo.size
    counts = np.bincount(actor_rows.astype(np.int64), minlength=0) if size else np.zeros(0, np.int64)
    per_actor = {names.get(i, f"#{i}"): int(n) for i, n in enumerate(counts) if n}
    rates = stats.get("rates", {})
    samples_per_s = float(rates.get("samples_per_s", 0.0))
    sampled, sampled_demo = int(stats.get("sampled_rows", 0)), int(stats.get("sampled_demo_rows", 0))
    demo_buffer, demo_recent = float(stats["demo_share_buffer"]), float(stats["demo_share_recent_samples"])
    online_size = stats["tables"]["online"]["size"]
    # Only a mode that samples demos has demo items in "the buffer"; the online share is the rest.
    online_buffer = (1.0 - demo_buffer) if online_size else 0.0
    online_recent = (1.0 - demo_recent) if sampled > sampled_demo else 0.0
    checkpoint = stats.get("checkpoint") or {}
    return {
        "online": {
            "inserts_per_s": float(rates.get("inserts_per_s", 0.0)),
            "samples_per_s": round(samples_per_s * online_recent, 1),
            "sampled_rows": sampled - sampled_demo,
            "share_buffer": online_buffer,
            "share_recent_samples": online_recent,
            "items_per_actor": dict(sorted(per_actor.items())),
            "rate_limiter": stats.get("rate_limiter"),
            "checkpoint_age_s": checkpoint.get("age_s"),
        },
        "demo": {
            "capacity": demo_region,  # a fixed region: never inserted into, never evicted
            "inserts_per_s": 0.0,
            "samples_per_s": round(samples_per_s * demo_recent, 1),
            "sampled_rows": sampled_demo,
            "share_buffer": demo_buffer,
            "share_recent_samples": demo_recent,
        },
    }


def full_stats(core: ReplayCore) -> dict:
    """``core.stats()`` unchanged, with each table's per-table view merged into ``tables.<name>``."""
    stats = core.stats(all_actors=True)
    views = _table_views(core, stats)
    for name, view in views.items():
        table = stats["tables"].setdefault(name, {})
        for key, value in view.items():
            table.setdefault(key, value)  # whatever core.stats() already says wins
    return stats


def read_items(core: ReplayCore, name: str, offset: int, limit: int, include_obs: bool) -> dict:
    """A page of decoded items; every row is copied out under the core's lock (whole items only)."""
    if name not in TABLES:
        raise KeyError(name)
    online = name == "online"
    with core._lock:
        table = core.online if online else core.demo
        total = table.size
        first = table.tail if online else 0  # key of the oldest item
        n = max(0, min(limit, total - offset))
        keys = np.arange(first + offset, first + offset + n, dtype=np.int64) if n else np.zeros(0, np.int64)
        rows = keys % table.capacity if online else keys
        cols = ["action", "reward", "steps", "terminated"] + (["truncated", "actor", "version", "key"] if online else [])
        if include_obs:
            cols += ["obs", "next_obs"]
        data = {c: getattr(table, c)[rows].copy() for c in cols}  # fancy indexing copies; .copy() is explicit
        tree = getattr(core, "tree", None)  # prioritized sampler: leaves are [demo rows | online rows]
        if tree is not None and n:
            data["priority"] = np.asarray(tree.get((core.demo.size + rows) if online else rows), np.float64).copy()
        names = {i: a for a, i in core._actor_index.items()} if online else {}
    obs = _obs_lists(data["obs"]) if include_obs else None
    next_obs = _obs_lists(data["next_obs"]) if include_obs else None
    items = []
    for j in range(n):
        item: dict[str, Any] = {"key": int(data["key"][j] if online else keys[j])}
        if online:
            idx = int(data["actor"][j])
            item["actor"] = names.get(idx, f"#{idx}")
            item["weights_version"] = int(data["version"][j])
        item["action"] = int(data["action"][j])
        item["reward"] = _f32(data["reward"][j])
        item["steps"] = int(data["steps"][j])
        item["terminated"] = bool(data["terminated"][j])
        if online:
            item["truncated"] = bool(data["truncated"][j])
        if "priority" in data:
            item["priority"] = float(data["priority"][j])
        if include_obs:
            item["obs"] = obs[j]
            item["next_obs"] = next_obs[j]
        items.append(item)
    end = offset + n
    return {
        "table": name, "offset": offset, "limit": limit, "total": total,
        "oldest_key": first if total else None, "newest_key": first + total - 1 if total else None,
        "next_offset": end if end < total else None, "include_obs": include_obs,
        "obs_shape": list(core.schema.obs_shape), "obs_dtype": core.schema.obs_dtype, "items": items,
    }


def demo_info(core: ReplayCore) -> dict:
    held, region = core.demo_held, core.demo
    meta = dict(held.metadata)
    return {
        "mode": core.mode,
        "phase": core.phase,
        "loaded": held.size > 0,
        "sha256": held.sha256 or None,
        "sha256_scheme": meta.get("sha256_scheme"),
        "held_items": held.size,
        "held_bytes": held.nbytes,
        "buffer_items": region.size,
        "buffer_bytes": region.nbytes,
        "sampled": core.demos_sampled,
        "obs_shape": list(core.schema.obs_shape),
        "obs_dtype": core.schema.obs_dtype,
        "metadata": meta,
    }


# --------------------------------------------------------------------------- Prometheus (prometheus_client)


def _family(kind: str, name: str, help_text: str, samples: list[tuple[dict[str, Any], Any]],
            ) -> GaugeMetricFamily | CounterMetricFamily:
    """One metric family; samples whose value is None (does not exist yet) are left out."""
    labels = list(samples[0][0]) if samples else []
    family = {"gauge": GaugeMetricFamily, "counter": CounterMetricFamily}[kind](
        "laneshift_replay_" + name, help_text, labels=labels)
    for label_values, value in samples:
        if value is not None:
            family.add_metric([str(label_values[k]) for k in labels], float(value))
    return family


def stats_metrics(stats: dict) -> list:
    """``full_stats()`` as metric families (the counters are the core's own, read at scrape time)."""
    t = stats["tables"]
    rl, ckpt = stats.get("rate_limiter") or {}, stats.get("checkpoint") or {}
    actors = sorted(stats.get("actors", {}).items())
    in_buffer = t["online"].get("items_per_actor", {})

    def per_table(key: str) -> list:
        return [({"table": n}, t[n].get(key)) for n in TABLES]

    def by(label: str, counts: dict) -> list:
        return [({label: k}, v) for k, v in sorted(counts.items())]

    def one(value: Any) -> list:
        return [({}, value)]

    out = [
        _family("gauge", "info", "Constant 1, labelled with the demo mode and the demo shard's sha256.",
                [({"mode": stats["mode"], "demo_sha256": t["demo"].get("sha256", "")}, 1)]),
        _family("gauge", "phase", "Rehearsal phase (1: demos only, 2: online); 0 in the other modes.",
                one(stats["phase"])),
        _family("gauge", "uptime_seconds", "Seconds since the replay core started.", one(stats["uptime_s"])),
        _family("gauge", "table_size", "Items in each table that sampling can draw.", per_table("size")),
        _family("gauge", "table_capacity", "Items each table can hold (demo: its fixed region).",
                per_table("capacity")),
        _family("gauge", "table_bytes", "Bytes held by each table (demo: the whole loaded shard).",
                per_table("bytes")),
        _family("gauge", "demo_held_items", "Demo transitions loaded from the shard(s).", one(t["demo"].get("held"))),
        _family("counter", "inserted", "Items ever inserted into the online table.",
                [({"table": "online"}, t["online"]["inserted"])]),
        _family("counter", "sampled_rows", "Rows sampled, by the table they came from.", per_table("sampled_rows")),
        _family("counter", "sample_requests", "Sample requests, by outcome.", by("result", stats.get("requests", {}))),
        _family("counter", "rejected", "Messages refused, by reason.", by("reason", stats.get("rejected", {}))),
        _family("counter", "dropped", "Valid items deliberately not stored, by reason.",
                by("reason", stats.get("dropped", {}))),
        _family("gauge", "demo_share_ratio", "Share of demo items in the sampled buffer and in recent sampled rows.",
                [({"scope": "buffer"}, stats["demo_share_buffer"]),
                 ({"scope": "recent_samples"}, stats["demo_share_recent_samples"])]),
        _family("gauge", "actor_buffer_items", "Online items in the buffer now, by actor.",
                [({"actor": a}, in_buffer.get(a, 0)) for a, _ in actors]),
    ]
    for field, kind, name, help_text in (
            ("items", "counter", "actor_items", "Items received, by actor."),
            ("stored", "counter", "actor_stored", "Items stored, by actor."),
            ("batches", "counter", "actor_batches", "Transition messages received, by actor."),
            ("lost_batches", "counter", "actor_lost_batches", "Messages missing from the sequence, by actor."),
            ("lost_items", "counter", "actor_lost_items",
             "Items in the missing messages (from the actor's env-step count), by actor."),
            ("env_steps", "counter", "actor_env_steps", "An actor's cumulative env steps."),
            ("last_version", "gauge", "actor_weights_version", "Newest weights version an actor acted with.")):
        out.append(_family(kind, name, help_text, [({"actor": a}, s.get(field)) for a, s in actors]))
    out += [
        _family("gauge", "rate_limiter_insert_ok", "1 while actors may insert.", one(rl.get("insert_ok"))),
        _family("gauge", "rate_limiter_size_ok", "1 once the online table has min_size items.", one(rl.get("size_ok"))),
        _family("gauge", "rate_limiter_rows_owed", "Rows the learner may still sample (absent without a ratio).",
                one(rl.get("rows_owed_to_learner"))),
        _family("gauge", "rate_limiter_samples_per_insert", "Configured sampled rows per inserted item.",
                one(rl.get("samples_per_insert"))),
        _family("gauge", "rate_limiter_tolerance_rows", "Configured slack either side of the ratio.",
                one(rl.get("tolerance"))),
        _family("gauge", "rate_limiter_min_size", "Online items needed before sampling.", one(rl.get("min_size"))),
        _family("gauge", "checkpoint_age_seconds", "Seconds since the last checkpoint (absent before the first).",
                one(ckpt.get("age_s"))),
        _family("gauge", "checkpoint_items", "Items in the last checkpoint.", one(ckpt.get("items"))),
        _family("gauge", "checkpoint_duration_seconds", "How long the last checkpoint took.", one(ckpt.get("seconds"))),
        _family("counter", "checkpoint_failures", "Checkpoint writes that failed (e.g. a full disk).",
                one(ckpt.get("failures", 0))),
    ]
    return out


def sample_latency_metric(latency: Any) -> HistogramMetricFamily:
    """The sample queryable's time per query (``service.SampleLatency``; no samples without one)."""
    family = HistogramMetricFamily("laneshift_replay_sample_duration_seconds",
                                   "Time the replay server spent answering one sample query (decode, sample, "
                                   "encode), by result (batch or error).", labels=["result"])
    if latency is not None:
        for result, (counts, total) in sorted(latency.snapshot().items()):
            cumulative = np.cumsum(counts).tolist()
            buckets = [(repr(le), c) for le, c in zip(latency.BUCKETS, cumulative)] + [("+Inf", cumulative[-1])]
            family.add_metric([result], buckets, total)
    return family


class _CoreCollector:
    """Everything ``/metrics`` shows of a core, read at scrape time (prometheus_client calls ``collect``)."""

    def __init__(self, core: ReplayCore):
        self.core = core

    def collect(self):
        yield from stats_metrics(full_stats(self.core))
        yield sample_latency_metric(getattr(self.core, "sample_latency", None))


def metrics_registry(core: ReplayCore) -> CollectorRegistry:
    """A registry of its own per app (not prometheus_client's global one): the core's metrics and
    this process's ``process_*`` metrics (CPU seconds, resident memory, open fds, start time)."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_CoreCollector(core))
    ProcessCollector(registry=registry)
    return registry


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
        got = core._lock.acquire(timeout=HEALTH_LOCK_TIMEOUT_S)
        try:
            body = {"status": "ok" if got else "unavailable", "mode": core.mode, "phase": core.phase,
                    "uptime_s": round(time.monotonic() - core.started, 3),
                    "online_size": core.online.size}
        finally:
            if got:
                core._lock.release()
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
        from .service import ReplayService  # zenoh and the config: loaded already in a replay server

        return SafeJSONResponse(ReplayService.info_of(core, core.identity.get("run_id")))

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
