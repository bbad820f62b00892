"""A run's end records on a run dir that filled up: the room the launcher keeps for them
(``deploy.run_dir.SpaceReserve``), the replay's final stats written by the launcher when the
server could not (``deploy.launch.write_end_records``), and the summary's line and record of every
failed write (``deploy.summary``). The whole run on a real full disk is ``laneshift chaos --faults
disk-full`` (root and a tmpfs; tests/test_chaos_suite.py).

Room: tests, unit. May import: deploy, the contract.
"""

from __future__ import annotations

import io
import json

from laneshift.config import load_run_config
from laneshift.deploy.launch import write_end_records
from laneshift.deploy.run_dir import SpaceReserve
from laneshift.deploy.summary import RunEnd, summarise, write_failures


def test_the_reserve_holds_real_bytes_until_released(tmp_path):
    reserve = SpaceReserve(tmp_path, size=64 * 1024)
    assert reserve.hold(io.StringIO())
    assert reserve.path.stat().st_size == 64 * 1024
    assert reserve.path.stat().st_blocks * 512 >= 64 * 1024  # written, not a hole
    reserve.release()
    assert not reserve.path.exists()
    reserve.release()  # twice is harmless (the launcher's finally)


def test_a_reserve_that_cannot_be_written_is_one_line_and_the_run_goes_on(tmp_path):
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("x")
    out = io.StringIO()
    assert not SpaceReserve(not_a_dir).hold(out)
    assert out.getvalue().count("\n") == 1 and "no room kept for the end records" in out.getvalue()


def test_the_launcher_writes_the_replays_final_stats_the_server_could_not(tmp_path):
    stats = {"tables": {"online": {"inserted": 8000}}, "checkpoint": {"failures": 3}}
    (tmp_path / "replay_stats_shard1.json").write_text('{"tables": {"onl')  # cut short by a full disk
    (tmp_path / "replay_stats_shard2.json").write_text(json.dumps({"written": "by the server"}))
    finals = {"replay_stats_shard0.json": stats, "replay_stats_shard1.json": stats,
              "replay_stats_shard2.json": stats}
    write_end_records(tmp_path, {"env_steps": 8000}, finals, io.StringIO())
    assert json.loads((tmp_path / "summary.json").read_text()) == {"env_steps": 8000}
    assert json.loads((tmp_path / "replay_stats_shard0.json").read_text()) == stats  # missing: written
    assert json.loads((tmp_path / "replay_stats_shard1.json").read_text()) == stats  # torn: rewritten
    assert json.loads((tmp_path / "replay_stats_shard2.json").read_text()) == {"written": "by the server"}


def test_an_end_record_that_cannot_be_written_is_said_in_one_line(tmp_path):
    out = io.StringIO()
    write_end_records(tmp_path / "gone", {"env_steps": 1}, {}, out)
    assert out.getvalue().startswith("train: could not write ") and out.getvalue().count("\n") == 1


def test_the_summary_counts_every_failed_write_by_kind_and_says_so(tmp_path):
    replay = {"tables": {"online": {"inserted": 100}}, "checkpoint": {"failures": 4}, "wal": {"failures": 2},
              "actors": {}, "actors_total": {"lost_batches": 0, "lost_items": 0}}
    learner = {"updates": 10, "version": 3, "checkpoint_failures": 1, "metrics_write_failures": 57}
    assert write_failures(replay, learner) == {"replay_checkpoints": 4, "write_ahead_log_records": 2,
                                               "learner_checkpoints": 1, "metrics_records": 57}
    cfg = load_run_config(overrides={"train.run_dir": str(tmp_path), "train.eval_episodes": 0, "actor.workers": 1})
    worker = {"name": "w0", "env_steps": 100, "episodes": 2, "batches": 2}
    end = RunEnd(cfg=cfg, workers=[worker], learner=learner, replay=replay, where={}, restarts={})
    out = io.StringIO()
    result = summarise(end, "done", 10.0, out)
    assert result["write_failures"]["metrics_records"] == 57
    line = next(x for x in out.getvalue().splitlines() if x.startswith("write failures"))
    assert "4 replay checkpoints" in line and "57 metrics records" in line and "2 write ahead log records" in line
    quiet = io.StringIO()
    summarise(end.__class__(**{**end.__dict__, "learner": {"updates": 1}, "replay": {"actors": {}}}),
              "done", 1.0, quiet)
    assert "write failures" not in quiet.getvalue()


def test_a_run_cut_short_with_its_ray_head_says_the_learners_count_and_its_last_checkpoint(tmp_path):
    """Ray's head gone with the workers (``Run._cluster_gone``): no worker's summary came back, so
    the env steps are the learner's last count, said as such, and the checkpoint shown is the last
    one the learner wrote (there is no final one)."""
    cfg = load_run_config(overrides={"train.run_dir": str(tmp_path), "train.eval_episodes": 5, "actor.workers": 2})
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "latest.safetensors").write_bytes(b"weights")
    learner = {"updates": 5220, "version": 104, "env_steps": 42880}
    end = RunEnd(cfg=cfg, workers=[], learner=learner, replay={}, where={}, restarts={})
    out = io.StringIO()
    result = summarise(end, "SIGTERM", 27.0, out)
    lines = out.getvalue().splitlines()
    steps = next(x for x in lines if x.startswith("env steps"))
    assert steps.startswith("env steps       42,880 in 27 s") and "2 of 2 workers ended without a summary" in steps
    assert result["env_steps"] == 42880 and result["eval"] is None  # cut short: no greedy evaluation
    assert next(x for x in lines if x.startswith("checkpoint")).endswith("checkpoints/latest.safetensors")
    # With every worker's summary, their own counts stand.
    workers = [{"name": f"w{i}", "env_steps": 21000, "episodes": 3, "batches": 1} for i in range(2)]
    out = io.StringIO()
    summarise(end.__class__(**{**end.__dict__, "workers": workers}), "SIGTERM", 27.0, out)
    assert "env steps       42,000 in 27 s" in out.getvalue() and "without a summary" not in out.getvalue()
