"""The experiment runner end to end at a tiny budget: real training runs, evaluation, table, curves.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import argparse
import json

from laneshift.tools.studies.experiments import register


def test_compare_runs_methods_and_seeds_and_writes_the_table(tmp_path):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args([
        "compare", "--scenario", "straight", "--methods", "none,dqfd", "--seeds", "0", "--env-steps", "1200",
        "--eval-episodes", "3", "--eval-max-steps", "40", "--out", str(tmp_path / "exp"),
        "--set", "replay.capacity=2000", "--set", "replay.min_size=200", "--set", "learner.hidden=32",
        "--set", "learner.batch_size=32", "--set", "replay.spi_tolerance=1024",
        # --set wins over the method's own settings (dqfd's 300,000-item buffer, 20,000 pre-training updates).
        "--set", "replay.demo_ratio=0.1", "--set", "learner.phase1_updates=100"])
    assert args.func(args) == 0
    results = json.loads((tmp_path / "exp" / "results.json").read_text())
    assert set(results["methods"]) == {"none", "dqfd"}
    for method in results["methods"].values():
        (run,) = method["runs"]
        for lane in ("random", "non-target"):
            assert run["eval"][lane]["episodes"] == 3
            assert method[lane]["survival"]["episodes"] == 3
            lo, hi = method[lane]["achievement"]["ci95"]
            assert 0.0 <= lo <= method[lane]["achievement"]["rate"] <= hi <= 1.0
    # The baselines ran on the same evaluation episodes; keep-lane never reaches the target from a non-target lane.
    assert results["baselines"]["keep-lane"]["non-target"]["achievement"]["rate"] == 0.0
    table = (tmp_path / "exp" / "table.md").read_text()
    assert "| dqfd | non-target |" in table and "| scripted (baseline) | random |" in table
    for name in ("curves_env_steps.png", "curves_wallclock.png", "table2.png"):
        assert (tmp_path / "exp" / name).read_bytes()[:4] == b"\x89PNG"
    # dqfd really used the margin loss and retention with demos.
    cfg = (tmp_path / "exp" / "dqfd-s0" / "config.yaml").read_text()
    assert "margin_loss_weight: 1.0" in cfg and "demo_mode: dqfd" in cfg and "n_step: 10" in cfg


def test_reward_presets_study_trains_each_condition_with_its_own_exploration(tmp_path):
    from laneshift.config import load_run_config
    from laneshift.tools.studies.reward_study import preset_overrides
    from laneshift.tools.studies.reward_study import register as register_presets

    # Table 1: condition 1 explores 1.0 -> 0.3, condition 5 1.0 -> 0.1.
    assert load_run_config(overrides=preset_overrides(1)).actor.epsilon_final == 0.3
    assert load_run_config(overrides=preset_overrides(5)).actor.epsilon_final == 0.1
    parser = argparse.ArgumentParser()
    register_presets(parser.add_subparsers())
    args = parser.parse_args([
        "presets", "--scenarios", "merge", "--presets", "1,5", "--env-steps", "800", "--eval-episodes", "2",
        "--out", str(tmp_path / "p"), "--set", "learner.hidden=32", "--set", "learner.batch_size=32",
        "--set", "replay.min_size=200", "--set", "replay.spi_tolerance=1024"])
    assert args.func(args) == 0
    results = json.loads((tmp_path / "p" / "results.json").read_text())
    assert set(results["runs"]) == {"merge-p1", "merge-p5"}
    for name, run in results["runs"].items():
        cfg = (tmp_path / "p" / name / "config.yaml").read_text()
        assert f"reward_preset: {run['preset']}" in cfg
        assert run["episodes"] > 0 and 0.0 <= run["eval"]["survival_rate"] <= 1.0
    assert "epsilon_final: 0.3" in (tmp_path / "p" / "merge-p1" / "config.yaml").read_text()
    assert (tmp_path / "p" / "returns.png").read_bytes()[:4] == b"\x89PNG"
    assert "| merge | 5 |" in (tmp_path / "p" / "table.md").read_text()


def test_train_method_applies_the_named_settings_under_mode_and_set(monkeypatch, capsys):
    """``laneshift train --method dqfd-bc`` is the experiment's settings in one flag; --set wins."""
    from laneshift.tools import cli
    from laneshift.deploy import local
    from laneshift.config import METHODS

    seen = {}
    monkeypatch.setattr(local, "train_local", lambda cfg, **kw: seen.setdefault("cfg", cfg) and 0)
    assert cli.main(["train", "--method", "dqfd-bc", "--set", "learner.dueling=false"]) == 0
    cfg = seen.pop("cfg")
    assert cfg.replay.demo_mode == "dqfd" and cfg.learner.n_step == METHODS["dqfd-bc"]["learner.n_step"] == 10
    assert cfg.learner.bc_loss_weight == 1.0 and cfg.replay.capacity == 300_000
    assert cfg.learner.dueling is False  # --set beats the method
    assert cli.main(["train", "--method", "dqfd", "--mode", "retention"]) == 0
    assert seen.pop("cfg").replay.demo_mode == "retention"  # so does --mode
    assert cli.main(["train", "--method", "dqfq"]) != 0 and "cfg" not in seen
    known = ", ".join(METHODS)  # every named method, in order
    assert f"--method: unknown 'dqfq' (known: {known})" in capsys.readouterr().err


def test_the_fade_method_is_the_shield_method_with_the_imitation_losses_fading_to_zero():
    """The published `*-imfade` networks were trained as dqfd-bc-alongside-safe-shield with
    learner.imitation_final=0: the preset of that name must be exactly those settings."""
    from laneshift.config import METHODS, load_run_config

    fade, shield = METHODS["dqfd-bc-alongside-safe-shield-fade"], METHODS["dqfd-bc-alongside-safe-shield"]
    assert fade == {**shield, "learner.imitation_final": 0.0}
    cfg = load_run_config(None, fade)
    assert cfg.learner.imitation_final == 0.0 and cfg.env.shield and cfg.learner.bc_loss_weight == 1.0
    assert cfg.learner.imitation_fade_steps == 0  # the fall ends with the budget


def test_the_human_like_stand_in_row_runs_on_the_test_episodes_of_both_lanes():
    from laneshift.config import EnvConfig
    from laneshift.tools.studies.table2 import HUMAN_LIKE_ROW, human_like_lanes

    rows = human_like_lanes(EnvConfig(scenario="straight", max_steps=30), episodes=2, seed=100_000)
    assert set(rows) == {"random", "non-target"} and "stand-in" in HUMAN_LIKE_ROW
    for lane in rows.values():
        assert lane["episodes"] == 2 and 0.0 <= lane["achievement_rate"] <= lane["survival_rate"] <= 1.0
