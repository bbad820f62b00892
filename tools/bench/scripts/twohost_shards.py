"""A benchmark, not a test: `laneshift bench shards` on the two-host setup of the cluster tests, as
against one host. Two network namespaces joined by a veth pair (tests/twohost.py, no Ray); the
router and the bench's own client (the learner's sampling path) in namespace A, shard i and
publisher j in namespace A or B by i (j) mod 2, every byte between them over the veth link. Then
the same bench in the root namespace on loopback, alternating two-host / one host. Needs root and
`ip netns`.

    .venv/bin/python tools/bench/scripts/twohost_shards.py [--shards 1,2,4] [--rounds 2]   # prints JSON

Both "hosts" share this machine's CPUs, so this measures what the network hop adds (the veth
link, the router's cross-namespace forwarding), not what two machines' cores would give.

Room: the tools (benchmarks: a script run by path from a checkout). May import: anything in laneshift,
the standard library, and the two-host harness of the tests (tests/twohost.py, by path).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path

spec = importlib.util.spec_from_file_location("twohost", Path(__file__).resolve().parents[3] / "tests" / "twohost.py")
twohost = importlib.util.module_from_spec(spec)
sys.modules["twohost"] = twohost
spec.loader.exec_module(twohost)


def bench(argv: list[str], ns: str | None) -> dict:
    cmd = [sys.executable, "-m", "laneshift", "bench", "shards", *argv, "--json"]
    if ns is not None:
        cmd = ["ip", "netns", "exec", ns, *cmd]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    if out.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr[-3000:]}")
    return json.loads(out.stdout)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--shards", default="1,2,4")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--duration", default="3")
    a = p.parse_args()
    common = ["--shards", a.shards, "--duration", a.duration]
    results = []
    with tempfile.TemporaryDirectory(prefix="ls-2h-shards-") as tmp, twohost.linked_namespaces(Path(tmp)) as (ns_a, ns_b):
        for rnd in range(a.rounds):
            for mode in ("two-host", "one host"):
                if mode == "two-host":
                    r = bench([*common, "--netns", f"{ns_a},{ns_b}", "--router-ip", twohost.HOST_A], ns_a)
                else:
                    r = bench(common, None)
                r["mode"], r["round"] = mode, rnd
                results.append(r)
                for row in r["rows"]:
                    print(json.dumps({"mode": mode, "round": rnd, "shards": row["shards"],
                                      "ingest_per_s": row["ingest_per_s"], "per_shard": row["ingest_per_shard"],
                                      "sample_idle_p50_p99_ms": [row["sample_idle"]["p50_ms"], row["sample_idle"]["p99_ms"]],
                                      "sample_under_ingest_p50_p99_ms": [row["sample_under_ingest"]["p50_ms"],
                                                                         row["sample_under_ingest"]["p99_ms"]],
                                      "lost_batches": row["lost_batches"], "never_stored": row["never_stored"],
                                      "router_cpu_us_per_transition": row["router_cpu_us_per_transition"]}), flush=True)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
