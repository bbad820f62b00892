"""`laneshift bench env`: JSON fields and the baseline evaluation (tiny runs).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import argparse
import json

from laneshift.tools.bench import env as bench_env


def test_json_output_has_the_required_fields(capsys) -> None:
    parser = argparse.ArgumentParser()
    bench_env.register(parser.add_subparsers())
    args = parser.parse_args(["env", "--steps", "20", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in (
        "laneshift_steps_per_s",
        "highway_fast_steps_per_s",
        "ratio",
        "laneshift_sim_s_per_wall_s",
        "highway_fast_sim_s_per_wall_s",
    ):
        assert out[key] > 0
    assert out["laneshift_step_sim_s"] == 0.1 and out["highway_fast_step_sim_s"] == 1.0


def test_baseline_rows() -> None:
    keep = bench_env.evaluate("keep-lane", "non-target", episodes=3, seed=0, max_steps=50)
    assert keep["achievement"] == 0.0 and 0.0 <= keep["survival"] <= 1.0
    scripted = bench_env.evaluate("scripted", "random", episodes=2, seed=0, max_steps=50)
    assert scripted["survival"] == 1.0
    lka = bench_env.lka_expert(episodes=3, seed=0)
    assert lka["survival"] == 1.0 and lka["demo_settle_s"] < 2.5
