"""`laneshift bench shards`: a tiny end-to-end run (a real router, 1 then 2 replay-server shard
processes, publisher processes, the learner's sharded client) returns every field, loses nothing
and leaves no process behind. No timing thresholds: speed depends on the machine.

Room: tests, system (real zenoh and laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import argparse
import json
import os

from laneshift.tools.bench import shards as bench_shards
from laneshift.deploy.processes import descendants


def test_bench_shards_json_end_to_end(capsys) -> None:
    parser = argparse.ArgumentParser()
    bench_shards.register(parser.add_subparsers())
    args = parser.parse_args(["shards", "--shards", "1,2", "--actors", "4", "--capacity", "4000",
                              "--duration", "0.5", "--json"])
    before = descendants(os.getpid())
    assert args.func(args) == 0
    result = json.loads(capsys.readouterr().out)
    assert [row["shards"] for row in result["rows"]] == [1, 2]
    for row in result["rows"]:
        assert len(row["ingest_per_shard"]) == row["shards"] and row["ingest_per_s"] > 0
        assert all(rate > 0 for rate in row["ingest_per_shard"])  # a0..a3 reach every shard
        assert row["lost_batches"] == 0 and row["rejected"] == 0 and row["never_stored"] == 0
        assert row["sample_idle"]["n"] >= 20 and row["sample_idle"]["p99_ms"] >= row["sample_idle"]["p50_ms"] > 0
        for floor in (row["floor_idle"], row["floor_under_ingest"]):  # the zero-work queryable answered
            assert floor["n"] >= 20 and floor["p99_ms"] >= floor["p50_ms"] > 0
    assert descendants(os.getpid()) == before  # every child process is gone
