"""The experiment runner end to end at a tiny budget: real training runs, evaluation, table, curves."""

from __future__ import annotations

import argparse
import json

from laneshift.experiments import register


def test_compare_runs_methods_and_seeds_and_writes_the_table(tmp_path):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args([
        "compare", "--scenario", "straight", "--methods", "none,dqfd", "--seeds", "0", "--env-steps", "1200",
        "--eval-episodes", "3", "--eval-max-steps", "40", "--out", str(tmp_path / "exp"),
        "--set", "replay.capacity=2000", "--set", "replay.min_size=200", "--set", "learner.hidden=32",
        "--set", "learner.batch_size=32", "--set", "replay.spi_tolerance=1024"])
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
    for name in ("curves_episodes.png", "curves_wallclock.png"):
        assert (tmp_path / "exp" / name).read_bytes()[:4] == b"\x89PNG"
    # dqfd really used the margin loss and retention with demos.
    cfg = (tmp_path / "exp" / "dqfd-s0" / "config.yaml").read_text()
    assert "margin_loss_weight: 1.0" in cfg and "demo_mode: dqfd" in cfg and "n_step: 10" in cfg
