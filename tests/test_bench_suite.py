"""`laneshift bench all`'s derived targets (``targets``; bench/suite.py says what each ``p*_`` key
measures) from its benchmarks' outputs: the arithmetic, and null where a benchmark did not run.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""
from __future__ import annotations

import pytest

from laneshift.tools.bench.suite import derive


def _shard_row(shards: int, per_s: float) -> dict:
    return {"shards": shards, "ingest_per_s": per_s, "server_cpu_us_per_transition": 1.0,
            "sample_idle": {"p99_ms": 4.0}, "sample_under_ingest": {"p99_ms": 9.0}}


def test_derive_computes_each_target_from_the_benchmarks():
    r = {"learner": {"cases": [{"name": "mlp-b256", "bare": {"updates_per_s": 150.0}, "learner_over_bare": 0.95,
                                "learner_over_bare_cpu": 0.97}]},
         "run": {"training_env_steps_per_s": 960.0, "steady_env_steps_per_s": 1080.0, "peak_tree_rss_mb": 1800, "peak_tree_pss_mb": 1300,
                 "first_stored_s": 14.0},
         "peers": {"rllib": {"env_steps_per_s": 80.0, "peak_tree_rss_mb": 2000},
                   "reverb": {"ingest_per_s": 1e4, "sample_idle": {"p99_ms": 30.0}}},
         "shards": {"rows": [_shard_row(1, 2e5), _shard_row(2, 3e5)]},
         "ingest_1024": {"rows": [_shard_row(1, 1.05e6)]}}
    t = derive(r)
    assert t["run_vs_bound_bound_env_steps_per_s"] == 150.0 * 256 / 32 == 1200.0
    assert t["run_vs_bound_fraction_of_bound"] == 0.9 and t["run_vs_bound_whole_training_fraction_of_bound"] == 0.8
    assert t["vs_rllib_env_steps"] == 12.0 and t["vs_rllib_rss"] == 0.9
    assert t["ingest_per_s_1024_per_message"] == 1.05e6
    assert t["vs_reverb_ingest"] == 20.0 and t["reverb_sample_p99_idle_ms"] == 30.0
    assert [row["shards"] for row in t["ingest_by_shard_count"]] == [1, 2]
    assert t["ingest_by_shard_count"][0]["sample_p99_idle_ms"] == 4.0


def test_derive_leaves_null_what_did_not_run():
    r = {"learner": {"error": "x"}, "run": {"error": "x"},
         "peers": {"rllib": {"skipped": "no venv"}, "reverb": {"skipped": "no venv"}},
         "shards": {"error": "x"}, "ingest_1024": {"error": "x"}}
    t = derive(r)
    assert t["run_vs_bound_fraction_of_bound"] is None and t["vs_rllib_env_steps"] is None
    assert t["ingest_per_s_1024_per_message"] is None and t["ingest_by_shard_count"] == []
    assert t["vs_reverb_ingest"] is None and t["reverb_ingest_per_s"] is None


def test_training_rate_reads_the_whole_of_training_and_its_last_two_thirds(tmp_path):
    import json

    from laneshift.tools.bench.run import training_rate

    # 0-10 s: a slow ramp (100 env steps/s); 10-30 s: steady at 1,000/s, 125 updates/s.
    recs = [{"kind": "learner", "time": 100.0 + t, "env_steps": 100 * t if t <= 10 else 1000 + 1000 * (t - 10),
             "updates": 0 if t <= 10 else 125 * (t - 10)} for t in range(0, 31)]
    recs.insert(0, {"kind": "learner", "time": 99.0, "env_steps": 0, "updates": 0})  # before any env step: left out
    recs.insert(5, {"kind": "worker", "time": 104.5})
    (tmp_path / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in recs) + "\n")
    r = training_rate(tmp_path)
    assert r["training_s"] == 29.0 and r["training_env_steps_per_s"] == round((21000 - 100) / 29, 1)
    assert r["steady_s"] == 19.0 and r["steady_env_steps_per_s"] == 1000.0 and r["steady_updates_per_s"] == 125.0


def test_bench_run_refuses_a_run_dir_of_its_own():
    import pytest

    from laneshift.tools.bench.run import bench_run

    with pytest.raises(SystemExit, match="must not hold --run-dir"):
        bench_run("--workers 2 --run-dir=/tmp/somewhere")


def test_the_waits_say_which_side_bounded_the_run():
    from laneshift.config import load_run_config
    from laneshift.deploy.summary import wait_shares, waits_line

    workers = [{"name": "w0", "env_steps": 10, "wall_s": 10.0, "rate_limited_s": 6.0},
               {"name": "w1", "env_steps": 10, "wall_s": 10.0, "rate_limited_s": 7.0}]
    learner = {"sample_wait_s": 0.5, "elapsed_s": 10.0}
    assert wait_shares(workers, learner) == {"workers_rate_limited_share": 0.65, "learner_sample_wait_share": 0.05}
    line = waits_line(load_run_config(), wait_shares(workers, learner))
    assert line == ["waits           workers 65% of their time on the rate limiter, learner 5% waiting for samples: "
                    "the learner bounded the run"]
    assert "the workers bounded the run" in waits_line(load_run_config(), wait_shares(
        [dict(workers[0], rate_limited_s=0.1)], {"sample_wait_s": 4.0, "elapsed_s": 10.0}))[0]
    sync = load_run_config(overrides={"train.parallel": "sync"})
    assert waits_line(sync, wait_shares(workers, learner)) == []  # sync waits by design
    # From its first batch on: the 2 s the learner waited for the replay to fill are not the workers'.
    filled = {"sample_wait_s": 2.3, "elapsed_s": 12.0, "training_s": 10.0, "training_wait_s": 0.3}
    assert wait_shares(workers, filled)["learner_sample_wait_share"] == 0.03


def test_derive_bounds_the_run_by_the_bare_loop_before_and_after_the_run():
    r = {"learner": {"cases": [{"name": "mlp-b256", "bare": {"updates_per_s": 140.0}}]},
         "bare_after_run": {"updates_per_s": 160.0},
         "run": {"training_env_steps_per_s": 960.0, "steady_env_steps_per_s": 1080.0},
         "peers": {"rllib": {"skipped": "no venv"}, "reverb": {"skipped": "no venv"}}}
    t = derive(r)
    assert t["run_vs_bound_bound_env_steps_per_s"] == 150.0 * 256 / 32 == 1200.0 and t["run_vs_bound_fraction_of_bound"] == 0.9
    assert t["run_vs_bound_bare_before_after"] == [140.0, 160.0] and t["run_vs_bound_bound_resolved"] is False  # 14 % apart
    r["bare_after_run"] = {"updates_per_s": 150.0}
    assert derive(r)["run_vs_bound_bound_resolved"] is True  # 7 % apart: within MAX_BARE_DRIFT
    r["bare_after_run"] = {"updates_per_s": None}  # the second measurement failed: the first alone
    assert derive(r)["run_vs_bound_bound_env_steps_per_s"] == 140.0 * 8 and derive(r)["run_vs_bound_bound_resolved"] is False


def test_bench_run_vs_bound_flags_rounds_whose_bound_moved_and_summarises_the_rest(monkeypatch):
    """Bare loop 100, 104, 160, 158 around three runs: the middle round's bound moved 54 % and its
    fraction reads 1.14; it is listed, flagged, and left out of the resolved summary."""
    from laneshift.tools.bench import run_vs_bound

    bares = iter([100.0, 104.0, 160.0, 158.0])
    runs = iter([700.0, 1200.0, 1000.0])
    monkeypatch.setattr(run_vs_bound, "bare_updates_per_s", lambda seconds, said_by: next(bares))
    monkeypatch.setattr(run_vs_bound, "bench_run", lambda args: {"rc": 0, "steady_env_steps_per_s": (x := next(runs)),
                                                                 "training_env_steps_per_s": x})
    r = run_vs_bound.bench_run_vs_bound(rounds=3, ratio=32.0)
    assert [row["resolved"] for row in r["rounds"]] == [True, False, True]
    # 700 / (102 x 256 / 32), 1200 / (132 x 8), 1000 / (159 x 8)
    assert [row["steady_fraction"] for row in r["rounds"]] == [0.86, 1.14, 0.79]
    resolved = r["run_vs_bound_steady_fraction_resolved"]
    assert r["rounds_resolved"] == 2 and (resolved["min"], resolved["max"]) == (0.79, 0.86)
    assert resolved["median"] == pytest.approx(0.825)
    assert r["run_vs_bound_steady_fraction"]["max"] == 1.14  # every round is still listed
    text = run_vs_bound.render(r)
    assert "(!)" in text and "2 of 3" in text


def test_bench_p1_is_a_hidden_old_name_that_says_the_new_one(monkeypatch, capsys):
    """`laneshift bench p1` runs `bench run-vs-bound` after one line naming it, and `laneshift bench
    --help` lists only the new name."""
    from laneshift.tools.bench import run_vs_bound
    from laneshift.tools.cli import build_parser

    ran = []
    monkeypatch.setattr(run_vs_bound, "bench_run_vs_bound", lambda *a: ran.append(a) or {"rounds": []})
    monkeypatch.setattr(run_vs_bound, "render", lambda r: "rendered")
    args = build_parser().parse_args(["bench", "p1", "--rounds", "3"])
    assert args.func(args) == 0 and ran == [(3, 40_000, 32.0, "--workers 2", 3.0)]
    out, err = capsys.readouterr()
    assert err.splitlines() == ["laneshift bench p1 is now `laneshift bench run-vs-bound`"] and out == "rendered\n"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "--help"])
    listing = capsys.readouterr().out
    assert "run-vs-bound" in listing and " p1 " not in listing
