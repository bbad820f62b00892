"""``/metrics`` of the replay server, built with prometheus_client: metric families read from
``views.full_stats()`` at scrape time, on a registry of the app's own, plus the ``process_*``
collector. prometheus_client does the format's escaping, ``_total`` suffixes and histogram
buckets, so this module only says which numbers are which metrics (names prefixed
``laneshift_replay_``).

Room: replay_server (component). May import: prometheus_client, this package's core and views.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from prometheus_client import CollectorRegistry, ProcessCollector
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily

from .core import ReplayCore

from .http_models import TABLES
from .views import full_stats

PROMETHEUS_CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"


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


#: The families of one number each read from a section of the stats (absent while the section has no
#: such key): (key, kind, name, help) for the rate limiter's, the last checkpoint's and the log's.
_RATE_LIMITER = (
    ("insert_ok", "gauge", "rate_limiter_insert_ok", "1 while actors may insert."),
    ("size_ok", "gauge", "rate_limiter_size_ok", "1 once the online table has min_size items."),
    ("rows_owed_to_learner", "gauge", "rate_limiter_rows_owed",
     "Rows the learner may still sample (absent without a ratio)."),
    ("samples_per_insert", "gauge", "rate_limiter_samples_per_insert", "Configured sampled rows per inserted item."),
    ("tolerance", "gauge", "rate_limiter_tolerance_rows", "Configured slack either side of the ratio."),
    ("min_size", "gauge", "rate_limiter_min_size", "Online items needed before sampling."))
_CHECKPOINT = (
    ("age_s", "gauge", "checkpoint_age_seconds", "Seconds since the last checkpoint (absent before the first)."),
    ("items", "gauge", "checkpoint_items", "Items in the last checkpoint."),
    ("seconds", "gauge", "checkpoint_duration_seconds", "How long the last checkpoint took."),
    ("failures", "counter", "checkpoint_failures", "Checkpoint writes that failed (e.g. a full disk)."))
_WAL = (
    ("bytes", "gauge", "wal_bytes", "Bytes of write-ahead log a restart would replay (absent without a log)."),
    ("records_written", "counter", "wal_records", "Records written to the write-ahead log (absent without a log)."),
    ("failures", "counter", "wal_failures", "Write-ahead log writes that failed (e.g. a full disk)."))


def stats_metrics(stats: dict) -> list:
    """``full_stats()`` as metric families (the counters are the core's own, read at scrape time)."""
    t = stats["tables"]
    rl, ckpt, wal = stats.get("rate_limiter") or {}, stats.get("checkpoint") or {}, stats.get("wal") or {}
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
            ("duplicates", "counter", "actor_duplicates",
             "Messages received again that the server held already (ignored), by actor."),
            ("env_steps", "counter", "actor_env_steps", "An actor's cumulative env steps."),
            ("last_version", "gauge", "actor_weights_version", "Newest weights version an actor acted with.")):
        out.append(_family(kind, name, help_text, [({"actor": a}, s.get(field)) for a, s in actors]))
    ckpt = {"failures": 0, **ckpt}  # 0 failures shows before the first checkpoint too
    for section, fields in ((rl, _RATE_LIMITER), (ckpt, _CHECKPOINT), (wal, _WAL)):
        out += [_family(kind, name, help_text, one(section.get(key))) for key, kind, name, help_text in fields]
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
