"""Read-only views of a live replay core for inspection: the full stats with each table's view
(``full_stats``), stored items as JSON-ready rows (``read_items``, copied out under the core's
lock, so every item is whole while actors insert), the demo shard's metadata (``demo_info``).
The HTTP API and ``/metrics`` serve these; nothing here writes to the core.

Room: replay_server (component). May import: numpy, this package's core and JSON helpers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .core import ReplayCore

from .http_models import TABLES, _f32, _obs_lists


def _table_views(core: ReplayCore, stats: dict) -> dict[str, dict]:
    """Each table's rates, shares of the buffer and of recent samples, items per actor, rate limiter
    and checkpoint age (docs/replay-api.md, ``/stats``), computed from ``stats`` plus the online
    table's actor column."""
    with core.lock:
        size = core.online.size
        actor_rows = core.online.actor[:size].copy()  # rows of live items: keys are contiguous
        names = {i: name for name, i in core.actor_index.items()}
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
    with core.lock:
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
        if core.prioritized and n:  # the sampler's leaves are [demo rows | online rows]
            data["priority"] = core.selector.priority_of((core.demo.size + rows) if online else rows)
        names = {i: a for a, i in core.actor_index.items()} if online else {}
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
