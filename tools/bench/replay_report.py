"""The text form of ``bench replay``'s result (``laneshift bench replay`` without ``--json``):
ingest, sample latency, memory per transition and the actor-scaling table, from the result dict
alone (docs/replay-bench.md prints stored results with it).

Room: the tools (benchmarks). May import: the standard library only.
"""

from __future__ import annotations

def _cores(c: dict) -> str:
    f = lambda k: "-" if c.get(k) is None else f"{c[k]:.2f}"  # noqa: E731
    return f"{f('server')}/{f('router')}/{f('publishers')}/{f('other')}"


def _loaded_lines(r: dict) -> list[str]:
    out = []
    for key, what in (("sample_under_paced_ingest", "2 actors paced to {:,.0f}/s"),
                      ("sample_under_saturating_ingest", "2 actors flat out")):
        x = r.get(key)
        if x is None:
            continue
        label = what.format(x.get("offered_per_s", 0)) + ":"
        out.append(f"  {label:33s} p50 {x['p50_ms']:.2f} ms  p99 {x['p99_ms']:.2f} ms  max {x['max_ms']:.1f} ms  "
                   f"(n={x['n']}; stored meanwhile {x['ingest_meanwhile']['ingest_per_s']:,.0f} /s)")
    return out


def format_result(r: dict) -> str:
    if "ingest_grayscale" not in r:  # --no-grayscale: the same lines, grayscale figures as 0
        zero = {"ingest_per_s": 0.0, "lost_batches": 0, "rejected": 0, "never_stored": 0, "cores": {}}
        r = {**r, "ingest_grayscale": zero, "fill_grayscale": zero, "ingest_grayscale_per_s": 0.0,
             "bytes_per_transition_grayscale": 0.0, "grayscale_obs": {"shape": ["-"], "dtype": "skipped"}}
    cfg, v, g = r["config"], r["ingest_vector"], r["ingest_grayscale"]
    yes = lambda ok: "met" if ok else "NOT met"  # noqa: E731
    vs, gs = "x".join(map(str, r["vector_obs"]["shape"])), "x".join(map(str, r["grayscale_obs"]["shape"]))
    lines = [
        f"replay bench: {cfg['topology']}; zenoh {cfg['zenoh']}, {cfg['cpus']} cpus, loopback",
        f"  replay servers: config defaults" + "".join(f", {k}={v}" for k, v in (cfg.get("replay_set") or {}).items())
        + f"; run dirs under {cfg.get('work_dir', '?')}",
        f"  {cfg['duration_s']:g} s per window after {cfg['warmup_s']:g} s warm-up, {cfg['batch']} transitions per "
        f"message, actors spread over {cfg['publisher_processes']} publisher processes, CongestionControl.BLOCK",
        "",
        "ingest (transitions stored by the server per second, 2 actors, steady state)",
        f"  vector    {r['vector_obs']['dtype']} ({vs}): {r['ingest_vector_per_s']:>10,.0f} /s   "
        f"target >= {r['targets']['ingest_vector_per_s']:,}: {yes(r['met']['ingest_vector'])}",
        f"  grayscale {r['grayscale_obs']['dtype']} ({gs}): {r['ingest_grayscale_per_s']:>8,.0f} /s   "
        f"({r['ingest_grayscale_per_s'] * r['bytes_per_transition_grayscale'] / 1e6:,.0f} MB/s stored)",
        f"  first fill of the table (every write on a fresh page): vector {r['fill_vector']['ingest_per_s']:,.0f} /s, "
        f"grayscale {r['fill_grayscale']['ingest_per_s']:,.0f} /s; the rates above are after it (ring wrapping)",
        f"  lost batches {v['lost_batches']} / {g['lost_batches']}, rejected {v['rejected']} / {g['rejected']}, "
        f"sent but never stored {v['never_stored']} / {g['never_stored']} (vector / grayscale)",
        "",
        f"sample latency, SampleRequest({cfg['sample_batch']}) on vector data, query to decoded batch",
        f"  {'idle server:':33s} p50 {r['sample_p50_ms']:.2f} ms  p99 {r['sample_p99_ms']:.2f} ms  "
        f"(n={r['sample_idle']['n']}, reply {r['sample_idle']['reply_bytes']:,} B)   "
        f"target p99 <= {r['targets']['sample_p99_ms']:g} ms: {yes(r['met']['sample_p99'])}",
        *_loaded_lines(r),
        "",
        f"memory per stored transition (online table bytes / capacity): "
        f"vector {r['bytes_per_transition_vector']:,.0f} B, grayscale {r['bytes_per_transition_grayscale']:,.0f} B",
        "",
        "actor scaling (vector): cores = server/router/publishers/other processes on the machine",
        f"  {'actors':>6s} {'transitions/s':>14s} {'us/transition':>14s} {'server CPU us/tr':>16s} {'msgs/s':>9s} "
        f"{'lost':>5s} {'rejected':>8s} {'never stored':>12s}  cores",
    ]
    for row in r["actor_scaling"]:
        us = "-" if row["us_per_transition"] is None else f"{row['us_per_transition']:.2f}"
        cpu = "-" if row["server_cpu_us_per_transition"] is None else f"{row['server_cpu_us_per_transition']:.2f}"
        lines.append(f"  {row['actors']:>6d} {row['ingest_per_s']:>14,.0f} {us:>14s} {cpu:>16s} "
                     f"{row['messages_per_s']:>9,.0f} {row['lost_batches']:>5d} {row['rejected']:>8d} "
                     f"{str(row['never_stored']):>12s}  {_cores(row['cores'])}")
    lines.append(f"\ncores during the 2-actor vector window: {_cores(v['cores'])}; grayscale: {_cores(g['cores'])}")
    lines.append(f"total wall time {r['wall_s']:.0f} s")
    return "\n".join(lines)

