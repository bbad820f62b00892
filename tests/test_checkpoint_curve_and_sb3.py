"""Learning curves from kept checkpoints, and the stable-baselines3 baseline on our env.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import json

import pytest

from laneshift.tools.studies.checkpoint_curve import evaluate_checkpoints, first_reaching, kept_checkpoints, render, select_best
from laneshift.config import EnvConfig, load_run_config
from laneshift.deploy.inprocess import train_inprocess


def test_kept_checkpoints_carry_their_training_budget_and_are_scored(tmp_path):
    cfg = load_run_config(overrides={
        "env.scenario": "lka", "actor.send_every": 50, "learner.hidden": "32,32", "learner.batch_size": 32,
        "learner.publish_every": 5, "learner.checkpoint_every": 50, "learner.keep_checkpoints": True,
        "replay.min_size": 100, "replay.samples_per_insert": 8, "replay.spi_tolerance": 512,
        "train.env_steps": 1500, "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    paths = kept_checkpoints(tmp_path)
    assert len(paths) == result["updates"] // 50 + 1 and paths[-1].name == "final.safetensors"
    rows = evaluate_checkpoints(tmp_path, EnvConfig(scenario="lka"), episodes=2, seed=7)
    updates = [r["updates"] for r in rows[:-1]]
    assert updates == sorted(updates) and updates[0] == 50
    assert all(0.0 <= r["random"]["survival_rate"] <= 1.0 for r in rows)
    assert "| u00000050.safetensors | 50 |" in render(rows, ("random",))
    assert first_reaching(rows, "random", "survival_rate", 2.0) is None
    # The command: a table, the validation-selected checkpoint, copied where asked.
    from laneshift.tools.cli import main
    from laneshift.config import save_run_config

    save_run_config(cfg, tmp_path / "config.yaml")
    best = tmp_path / "picked" / "best.safetensors"
    assert main(["experiment", "checkpoints", "--run-dir", str(tmp_path), "--episodes", "2", "--seed", "7",
                 "--initial-lanes", "random", "--copy-best", str(best)]) == 0
    saved = json.loads((tmp_path / "checkpoint_curve.json").read_text())
    assert saved["best"] == select_best(rows, ("random",))["checkpoint"]  # same episodes, same scores
    assert best.read_bytes() == (tmp_path / "checkpoints" / saved["best"]).read_bytes()


def _row(name: str, **lanes: tuple[float, float]) -> dict:
    return {"checkpoint": name, **{lane: {"survival_rate": s, "achievement_rate": a, "return_mean": 0.0}
                                   for lane, (s, a) in lanes.items()}}


def test_select_best_ranks_by_the_worst_initial_lane_then_survival_and_keeps_the_earliest():
    lanes = ("random", "non-target")
    rows = [_row("u1", random=(1.0, 0.98), **{"non-target": (0.9, 0.80)}),   # worst achievement 0.80
            _row("u2", random=(0.96, 0.90), **{"non-target": (0.94, 0.90)}),  # 0.90, worst survival 0.94
            _row("u3", random=(1.0, 0.92), **{"non-target": (0.98, 0.90)}),   # 0.90, worst survival 0.98
            _row("u4", random=(1.0, 0.90), **{"non-target": (0.98, 0.92)})]   # the same rates as u3, later
    assert select_best(rows, lanes)["checkpoint"] == "u3"
    assert select_best(rows[:2], lanes)["checkpoint"] == "u2"
    for lane in lanes:  # same rates, better worst-lane return: the later one
        rows[3][lane]["return_mean"] = 1.0
    assert select_best(rows, lanes)["checkpoint"] == "u4"
    lka = [{"checkpoint": n, "random": {"survival_rate": 1.0, "return_mean": r}} for n, r in [("a", -20.0), ("b", -9.0)]]
    assert select_best(lka, ("random",))["checkpoint"] == "b"


def test_sb3_dqn_trains_on_the_laneshift_env_and_reports_a_curve(tmp_path, capsys, monkeypatch):
    pytest.importorskip("stable_baselines3")  # optional extra [baselines]; `make` installs it
    import tempfile

    from laneshift.tools.studies.sb3_baseline import train_sb3

    # SB3's default logger would leave an empty SB3-<date> dir in the temp dir on every run.
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    res = train_sb3(EnvConfig(scenario="straight", max_steps=50), env_steps=400, eval_every=200, eval_episodes=2,
                    seed=0, eval_seed=5, out=tmp_path)
    assert [row["env_steps"] for row in res["curve"]] == [200, 400]
    assert set(res["curve"][0]) >= {"random", "non-target", "train_s"}
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["algorithm"] == "DQN" and saved["net_arch"] == [256, 256]
    assert (tmp_path / "sb3_dqn.zip").exists()
    assert not list(scratch.glob("SB3-*"))
