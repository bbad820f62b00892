"""``laneshift replay inspect``: the replay server's stats as a readable table.

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component."""

from __future__ import annotations

import argparse
import json
import time

from laneshift import transport, wire
from laneshift.config import TransportConfig
from laneshift.replay_stats import merge_replay_stats


def render(stats: dict) -> str:
    t = stats["tables"]
    lines = [
        f"mode {stats['mode']}  phase {stats['phase']}  uptime {stats['uptime_s']:.0f} s"
        f"  HTTP API {stats.get('http_url') or 'off'}",
        f"{'table':<8}{'size':>10}{'capacity':>10}{'inserted':>12}{'MiB':>8}",
        f"{'online':<8}{t['online']['size']:>10,}{t['online']['capacity']:>10,}{t['online']['inserted']:>12,}"
        f"{t['online']['bytes'] / 2**20:>8.1f}",
        f"{'demo':<8}{t['demo']['size']:>10,}{t['demo']['held']:>10,}{'-':>12}{t['demo']['bytes'] / 2**20:>8.1f}"
        f"  sha256 {t['demo']['sha256'][:16] or '-'}",
        f"demo share: buffer {stats['demo_share_buffer']:.3f}, recent samples {stats['demo_share_recent_samples']:.3f}",
        f"rates: {', '.join(f'{k} {v:,.0f}' for k, v in stats['rates'].items()) or '-'}",
        f"requests: {stats['requests'] or '-'}   rejected: {stats['rejected'] or '-'}   dropped: {stats['dropped'] or '-'}",
        f"{'actor':<10}{'batches':>9}{'items':>10}{'stored':>10}{'lost':>6}{'version':>9}{'env steps':>11}",
    ]
    for name, a in sorted(stats["actors"].items()):
        lines.append(f"{name:<10}{a['batches']:>9,}{a['items']:>10,}{a['stored']:>10,}{a['lost_batches']:>6}"
                     f"{a['last_version']:>9}{a['env_steps']:>11,}")
    for shard in stats.get("shards", []):  # a sharded replay: one line per shard
        lines.append(f"shard {shard['shard']}: {shard['online_size']:,} items, {shard['inserted']:,} inserted, "
                     f"{shard['actors']} actors, HTTP API {shard.get('http_url') or 'off'}")
    total = stats.get("actors_total")
    if total:
        more = total["count"] - len(stats["actors"])
        lines.append(f"{'all ' + str(total['count']):<10}{total['batches']:>9,}{total['items']:>10,}{total['stored']:>10,}"
                     f"{total['lost_batches']:>6}{total['max_version']:>9}{total['env_steps']:>11,}"
                     + (f"   ({more} more actors: /actors of the HTTP API)" if more > 0 else ""))
    return "\n".join(lines)


def inspect_main(args: argparse.Namespace) -> int:
    cfg = TransportConfig(router=args.router, run_id=args.run_id)
    shards = getattr(args, "shards", 1)
    one = getattr(args, "shard", None)
    if one is not None and not 0 <= one < shards:
        print(f"--shard {one}: the run has --shards {shards} (0 to {shards - 1})")
        return 2
    wanted = [one] if one is not None else list(range(shards))
    keys = [wire.replay_stats_key(wire.replay_namespace(cfg.run_id, i, shards)) for i in wanted]
    with transport.open_session(cfg) as session:
        while True:
            replies = [transport.query(session, key, b"", cfg.timeout_s) for key in keys]
            missing = [key for key, reply in zip(keys, replies) if reply is None]
            if missing:
                print(f"no replay server answered on {', '.join(missing)} via {cfg.router}")
                if not args.watch:
                    return 1
            else:
                # A sharded replay reads as one (every shard's counters summed, replay_stats.py).
                stats = merge_replay_stats([wire.decode_json(r) for r in replies])
                print(json.dumps(stats, indent=2) if args.json else render(stats), flush=True)
            if not args.watch:
                return 0
            time.sleep(args.interval)
            print()
