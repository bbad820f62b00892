"""The replay stats of a sharded replay as one: how the ``replay/stats`` bodies of N shards add up.

A run with ``replay.shards`` > 1 has N replay servers, each with its own counters. The learner's
progress (env steps, table size, demo share) and the launcher's summary (stored, lost, rejected)
read the run's replay as one, so this module sums what sums (items, counters, rates), takes the
extremes of what does not (phase, versions) and recomputes the shares from their parts. Each shard
stays visible in ``shards`` (a few numbers each, so the merged body stays small for 64 shards).

    >>> merged = merge_replay_stats([{"tables": {"online": {"size": 3}}}, {"tables": {"online": {"size": 4}}}])
    >>> merged["tables"]["online"]["size"], len(merged["shards"])
    (7, 2)

Room: the contract (shared by every process). May import: the standard library only.
"""

from __future__ import annotations

import collections
from typing import Any, Iterable

#: Actors listed in a merged body (as in one server's: replay_server/core.ACTORS_IN_STATS).
ACTORS_SHOWN = 32


def _sum_numbers(bodies: Iterable[dict]) -> dict[str, Any]:
    """Key by key: numbers summed, nested dicts merged the same way, anything else the first seen."""
    out: dict[str, Any] = {}
    for body in bodies:
        for key, value in (body or {}).items():
            if isinstance(value, bool) or value is None:
                out.setdefault(key, value)
            elif isinstance(value, (int, float)):
                out[key] = out.get(key, 0) + value if isinstance(out.get(key, 0), (int, float)) else value
            elif isinstance(value, dict):
                out[key] = _sum_numbers([out[key], value]) if isinstance(out.get(key), dict) else _sum_numbers([value])
            else:
                out.setdefault(key, value)
    return out


def merge_replay_stats(shards: list[dict], all_actors: bool = False) -> dict[str, Any]:
    """One stats body for the run's replay from each shard's (in shard order). ``actors`` lists
    the first ACTORS_SHOWN of the actors the bodies list, or all of them with ``all_actors`` (the
    final stats, which list every actor, for the run's summary)."""
    if len(shards) == 1:
        return shards[0]
    first = shards[0]
    online = [s.get("tables", {}).get("online", {}) for s in shards]
    demo = [s.get("tables", {}).get("demo", {}) for s in shards]
    demo_in = [int(s.get("demo_in_buffer", 0)) for s in shards]
    live = sum(int(o.get("size", 0)) for o in online) + sum(demo_in)
    sampled = sum(int(s.get("sampled_rows", 0)) for s in shards)
    sampled_demo = sum(int(s.get("sampled_demo_rows", 0)) for s in shards)
    # The recent demo share of each shard, weighted by how many rows it serves now.
    recent_w = [float(s.get("rates", {}).get("samples_per_s", 0.0)) for s in shards]
    recent = [float(s.get("demo_share_recent_samples", 0.0)) for s in shards]
    recent_share = (sum(w * r for w, r in zip(recent_w, recent)) / sum(recent_w)) if sum(recent_w) > 0 else \
        (sum(recent) / len(recent))
    totals = [s.get("actors_total", {}) for s in shards]
    actors_total = _sum_numbers([{k: v for k, v in t.items() if k not in ("min_version", "max_version")}
                                 for t in totals])
    versions = [t for t in totals if t.get("count")]
    actors_total["min_version"] = min((int(t.get("min_version", -1)) for t in versions), default=-1)
    actors_total["max_version"] = max((int(t.get("max_version", -1)) for t in versions), default=-1)
    actors: dict[str, Any] = {}
    for s in shards:
        actors.update(s.get("actors", {}))
    shown = sorted(actors) if all_actors else sorted(actors)[:ACTORS_SHOWN]
    samplers = [s.get("sampler", {}) for s in shards]
    max_priorities = [p.get("max_priority") for p in samplers if p.get("max_priority") is not None]
    return {
        **{k: first.get(k) for k in ("mode", "obs_shape", "obs_dtype", "n_actions", "http_url")},
        "phase": min(int(s.get("phase", 0)) for s in shards),
        "uptime_s": max(float(s.get("uptime_s", 0.0)) for s in shards),
        "tables": {
            "online": _sum_numbers(online),
            # Every shard holds the demo shard (the same file: one sha256); its demo region is its own.
            "demo": {**_sum_numbers(demo), "held": demo[0].get("held"), "sha256": demo[0].get("sha256")},
        },
        "demo_in_buffer": sum(demo_in),
        "demo_share_buffer": sum(demo_in) / live if live and first.get("mode") != "none" else 0.0,
        "demo_share_recent_samples": recent_share,
        "sampled_rows": sampled,
        "sampled_demo_rows": sampled_demo,
        "requests": dict(sum((collections.Counter(s.get("requests", {})) for s in shards), collections.Counter())),
        "sampler": {"kind": samplers[0].get("kind"),
                    "priority_updates": sum(int(p.get("priority_updates", 0)) for p in samplers),
                    "max_priority": max(max_priorities) if max_priorities else None},
        "rejected": dict(sum((collections.Counter(s.get("rejected", {})) for s in shards), collections.Counter())),
        "dropped": dict(sum((collections.Counter(s.get("dropped", {})) for s in shards), collections.Counter())),
        "actors": {k: actors[k] for k in shown},
        "actors_total": actors_total,
        "rates": _sum_numbers([s.get("rates", {}) for s in shards]),
        "shards": [{"shard": i, "online_size": int(o.get("size", 0)), "inserted": int(o.get("inserted", 0)),
                    "actors": int(t.get("count", 0)), "phase": s.get("phase"), "http_url": s.get("http_url"),
                    "rates": s.get("rates", {}), "rate_limiter": s.get("rate_limiter")}
                   for i, (s, o, t) in enumerate(zip(shards, online, totals))],
    }
