"""`laneshift bench replay`: a tiny end-to-end run (real router, replay-server and publisher
processes) returns every JSON field with sane values, and leaves no process behind. No timing
thresholds: speed depends on the machine.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
import pytest

from laneshift import wire
from laneshift.tools.bench import replay as bench_replay
from laneshift.tools.bench.replay_harness import SAMPLE_BATCH, synthetic_message
from laneshift.tools.bench.replay_report import format_result
from laneshift.deploy.processes import descendants


def test_bench_replay_json_end_to_end(capsys) -> None:
    parser = argparse.ArgumentParser()
    bench_replay.register(parser.add_subparsers())
    args = parser.parse_args(["replay", "--duration", "1.0", "--warmup", "0.2", "--actors", "2",
                              "--capacity-vector", "2000", "--capacity-grayscale", "300", "--paced-rate", "2000",
                              "--json"])
    before = descendants(os.getpid())
    assert args.func(args) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out.strip().splitlines()[-1])
    log = captured.err[-4000:]  # the bench's progress log: says why a publisher left no report

    for key in ("ingest_vector_per_s", "ingest_grayscale_per_s", "sample_p50_ms", "sample_p99_ms"):
        assert out[key] > 0, key
    assert out["sample_p50_ms"] <= out["sample_p99_ms"]
    assert out["vector_obs"] == {"shape": [82], "dtype": "<f4"}
    assert out["grayscale_obs"] == {"shape": [4, 100, 100], "dtype": "|u1"}
    # Bytes per stored transition: at least the two observations, plus a few fixed columns.
    assert 2 * 82 * 4 < out["bytes_per_transition_vector"] < 2 * 82 * 4 + 64
    # Grayscale: frames held once each (replay_server/frames.py), 2 frames of 10,000 B per item of capacity,
    # 2 x 4 frame keys and a frame floor of 8 B each.
    assert 2 * 10_000 < out["bytes_per_transition_grayscale"] < 2 * 10_000 + (2 * 4 + 1) * 8 + 64
    assert [row["actors"] for row in out["actor_scaling"]] == [2]
    for run in (out["ingest_vector"], out["ingest_grayscale"], *out["actor_scaling"],
                out["fill_vector"], out["fill_grayscale"]):
        assert run["ingest_per_s"] > 0 and run["stored_in_window"] > 0
        assert run["lost_batches"] == 0 and run["rejected"] == 0
        assert run["never_stored"] == 0 and run["sent"] == run["stored"] > 0, log  # BLOCK: nothing lost
    # A first-fill window opens before any publisher sends (start barrier), so it holds the whole fill.
    assert out["fill_vector"]["stored_in_window"] >= 2000
    assert out["fill_grayscale"]["stored_in_window"] >= 300
    for key in ("sample_under_saturating_ingest", "sample_under_paced_ingest"):
        lat = out[key]
        assert lat["n"] >= 5 and 0 < lat["p50_ms"] <= lat["p99_ms"] <= lat["max_ms"]
    assert out["sample_idle"]["reply_bytes"] > SAMPLE_BATCH * 2 * 82 * 4
    assert set(out["met"]) == {"ingest_vector", "sample_p99"}
    text = format_result(out)  # the text form renders from the same dict
    assert "actor scaling" in text and "sample latency" in text
    assert descendants(os.getpid()) <= before  # every router, server and publisher was stopped


def test_patched_messages_decode_with_their_counters() -> None:
    schema = wire.TransitionSchema((82,), "float32", 9)
    patcher = synthetic_message("w3", schema, 4, np.random.default_rng(0))
    for seq in (0, 1, 99, 123_456_789):
        batch = wire.decode_transitions(patcher.build(seq, (seq + 1) * 4), schema)
        assert (batch.actor, batch.seq, batch.env_steps, len(batch)) == ("w3", seq, (seq + 1) * 4, 4)


def test_a_bad_set_is_refused_before_any_process_starts() -> None:
    parser = argparse.ArgumentParser()
    bench_replay.register(parser.add_subparsers())
    args = parser.parse_args(["replay", "--set", "replay.wal=sometimes"])
    with pytest.raises(SystemExit, match=r"replay\.wal: must be off, write or fsync"):
        args.func(args)
