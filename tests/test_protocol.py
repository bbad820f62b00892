"""The evaluation protocol end to end at a tiny budget: a real training run validated on the
validation episodes, its final network tested, the baselines on the same test episodes, the table,
the published network with its provenance, a second invocation that skips the finished seed and a
third that adds the final network's rates on validation episodes;
the same for one network on all four roads (allroads: rows per road and initial lane, each road's
own test episodes); and the validation-curve measures (time to a threshold, the largest drop) and
the pooling of the four roads' evaluations on hand-made numbers.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import argparse
import json
import shlex
import time

import numpy as np
import pytest
import yaml

from laneshift.tools.studies.protocol import register
from laneshift.tools.studies.protocol_publish import eval_command
from laneshift.tools.studies.protocol_validation import VALIDATION_SEED, stability_drop, time_to_threshold

TINY = ["--set", "replay.capacity=2000", "--set", "replay.min_size=200", "--set", "learner.hidden=32",
        "--set", "learner.batch_size=32", "--set", "replay.spi_tolerance=1024",
        "--set", "replay.demo_ratio=0.1", "--set", "learner.phase1_updates=100"]


def _curve(points: list[tuple[int, float]]) -> list[dict]:
    return [{"env_steps": s, "elapsed_s": s / 100, "survival_rate": 1.0, "achievement_rate": a} for s, a in points]


def test_time_to_threshold_and_the_largest_drop_after_the_target_on_hand_made_curves():
    curve = _curve([(100, 0.5), (200, 0.85), (300, 0.8), (400, 0.95), (500, 0.9), (600, 0.97), (700, 0.88)])
    assert time_to_threshold(curve, 0.80) == {"env_steps": 200, "elapsed_s": 2.0}
    assert time_to_threshold(curve, 0.95) == {"env_steps": 400, "elapsed_s": 4.0}  # >= counts
    assert time_to_threshold(curve, 0.99) is None
    assert time_to_threshold([], 0.8) is None
    # From the first evaluation at or above 0.93 (0.95 at 400) on: best 0.95, then 0.97; 0.97 -> 0.88.
    assert stability_drop(curve, 0.93) == pytest.approx(0.09)
    # The dip before the target was reached (0.85 -> 0.8) does not count.
    assert stability_drop(_curve([(1, 0.85), (2, 0.5), (3, 0.94), (4, 0.93)]), 0.93) == pytest.approx(0.01)
    assert stability_drop(_curve([(1, 0.9), (2, 0.95), (3, 0.96), (4, 1.0)]), 0.93) == 0.0  # never fell
    assert stability_drop(curve, 0.99) is None and stability_drop([], 0.5) is None


def test_the_drop_that_evaluation_noise_alone_shows_beside_the_measured_one():
    from laneshift.tools.studies.protocol_validation import drop_noise

    curve = [{**r, "episodes": 20} for r in _curve([(100, 0.9), (200, 0.95), (300, 0.85), (400, 0.95), (500, 0.95)])]
    noise = drop_noise(curve, 0.93)
    # A policy at a constant 95 % measured on 20 episodes five times: a drop of 5-10 points is usual.
    assert 0.04 <= noise["median"] <= 0.1 and noise["p90"] >= noise["median"]
    assert stability_drop(curve, 0.93) == pytest.approx(0.1)  # the measured drop: within that noise
    many = drop_noise([{**r, "episodes": 400} for r in curve], 0.93)
    assert many["median"] < noise["median"] and many["p90"] < 0.05
    assert drop_noise(curve, 0.99) is None and drop_noise([], 0.5) is None


def test_the_validation_figure_is_the_mean_over_seeds(tmp_path):
    from laneshift.tools.studies.protocol_validation import plot_validation

    runs = [{"seed": seed, "validation": {"curve": [{**r, "episodes": 20} for r in _curve(points)]}}
            for seed, points in ((0, [(100, 0.5), (200, 0.9), (300, 0.95)]), (1, [(150, 0.2), (250, 0.7), (320, 0.9)]))]
    results = {"road": "straight", "method": "dqfd-bc", "methods": {"dqfd-bc": {"runs": runs}},
               "validation": {"episode_seed": VALIDATION_SEED}}
    assert plot_validation(results, tmp_path).read_bytes()[:4] == b"\x89PNG"
    runs[0]["validation"]["curve"] = runs[1]["validation"]["curve"] = runs[0]["validation"]["curve"][:1]
    assert plot_validation(results, tmp_path / "none") is None  # one evaluation each: no curve


def test_eval_command_names_every_env_field_eval_has_no_flag_for():
    env = {"scenario": "straight", "observation": "vector", "reward_preset": 5, "max_steps": 0,
           "initial_lane": "random", "action_set": "paper", "policy_vehicles": 3, "lane_features": False}
    cmd = shlex.split(eval_command("ckpt dir/a.safetensors", env, 200, 300, "non-target"))
    assert cmd[:4] == ["laneshift", "eval", "--checkpoint", "ckpt dir/a.safetensors"]
    assert cmd[cmd.index("--seed") + 1] == "100000" and cmd[cmd.index("--initial-lane") + 1] == "non-target"
    assert [cmd[i + 1] for i, a in enumerate(cmd) if a == "--set"] == ["env.policy_vehicles=3",
                                                                       "env.lane_features=false"]
    assert "--observation" not in cmd


def test_protocol_trains_tests_publishes_and_skips_a_finished_seed(tmp_path, capsys, monkeypatch):
    from laneshift.tools import cli

    out, pub = tmp_path / "proto", tmp_path / "published"
    argv = ["protocol", "--scenario", "straight", "--method", "dqfd", "--seeds", "0", "--env-steps", "2400",
            "--test-episodes", "3", "--eval-max-steps", "40", "--validation-every", "400",
            "--validation-episodes", "2", "--out", str(out), "--publish", str(pub), *TINY,
            "--set", "train.log_every_s=0.25"]  # the learner starts a due evaluation at its status line
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(argv)
    assert args.func(args) == 0
    results = json.loads((out / "results.json").read_text())
    (run,) = results["methods"]["dqfd"]["runs"]
    for lane in ("random", "non-target"):
        assert run["eval"][lane]["episodes"] == 3
        assert set(results["baselines"]) == {"scripted", "human-like stand-in"}
        assert results["baselines"]["scripted"][lane]["survival"]["episodes"] == 3  # the same test episodes
    table = (out / "table.md").read_text()
    assert "scripted driver" in table and "human-like stand-in" in table and "| non-target |" in table
    assert "80% validation achievement" in table and "largest drop after 93.0%" in table
    # The periodic evaluation ran on the validation episodes.
    cfg = yaml.safe_load((out / "dqfd-s0" / "config.yaml").read_text())
    assert cfg["train"]["validation_seed"] == VALIDATION_SEED == 200_000 and cfg["train"]["eval_every"] == 400
    curve = run["validation"]["curve"]
    assert curve and all(r["episodes"] == 2 and r["elapsed_s"] >= 0 for r in curve)
    # The figure needs two evaluations; how many fit in so short a run depends on the machine's load.
    assert (out / "curves_validation.png").is_file() == (len(curve) >= 2)
    assert run["validation"]["episode_seed"] == 200_000
    # The published network, with its provenance and test table.
    assert (pub / "straight-dqfd-seed0-final.safetensors").read_bytes() == \
        (out / "dqfd-s0" / "checkpoints" / "final.safetensors").read_bytes()
    doc = json.loads((pub / "straight-dqfd-seed0-final.json").read_text())
    assert len(doc["git"]["revision"]) == 40 and isinstance(doc["git"]["dirty"], bool)
    assert isinstance(doc["command"], str) and doc["config"]["train"]["validation_seed"] == 200_000
    assert doc["test"]["episode_seed"] == 100_000 and doc["test"]["max_steps"] == 40
    lane = doc["test"]["lanes"]["non-target"]
    assert lane["episodes"] == 3 and lane["survival_rate"] == run["eval"]["non-target"]["survival_rate"]
    # Its `laneshift eval` command gives the same rates.
    capsys.readouterr()
    assert cli.main(shlex.split(lane["command"])[1:] + ["--json"]) == 0
    again = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (again["survival_rate"], again["achievement_rate"]) == (lane["survival_rate"], lane["achievement_rate"])
    # The same command again: the seed is done, the baselines are kept; nothing trains.
    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")  # every bar line, at once
    began = time.monotonic()
    args = parser.parse_args(argv)
    assert args.func(args) == 0
    printed, bars = capsys.readouterr()
    assert f"protocol: dqfd seed 0: done ({out / 'dqfd-s0.json'}), skipped" in printed
    # The seed done before is where the bar starts, not a seed done now in no time (no rate, no time left).
    assert "protocol straight dqfd: 1/1 seed (100 %)" in bars and "?seed/s" in bars
    assert "baselines: kept from" in printed and time.monotonic() - began < 20
    assert json.loads((out / "results.json").read_text())["methods"]["dqfd"]["runs"] == [run]
    # Again with --final-validation-episodes: the done seed's final network and the drivers on the
    # validation episodes, added without training; the rates are `laneshift eval`'s on those episodes.
    assert cli.main(["experiment", *argv, "--final-validation-episodes", "2"]) == 0
    printed = capsys.readouterr().out
    assert "done" in printed and "The same final networks on the **validation episodes**" in printed
    results = json.loads((out / "results.json").read_text())
    (kept,) = results["methods"]["dqfd"]["runs"]
    assert kept["eval"] == run["eval"] and results["final_validation"]["test"]["episode_seed"] == VALIDATION_SEED
    validated = json.loads((out / "dqfd-s0.json").read_text())["final_validation"]
    assert validated["episodes_per_lane"] == 2 and validated["episode_seed"] == VALIDATION_SEED
    assert results["final_validation"]["baselines"]["scripted"]["random"]["survival"]["episodes"] == 2
    assert (out / "baselines-validation.json").is_file()
    assert cli.main(["eval", "--checkpoint", str(out / "dqfd-s0" / "checkpoints" / "final.safetensors"),
                     "--scenario", "straight", "--episodes", "2", "--seed", str(VALIDATION_SEED), "--max-steps", "40",
                     "--initial-lane", "non-target", "--json"]) == 0
    by_eval = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert by_eval["achievement_rate"] == validated["eval"]["non-target"]["achievement_rate"]
    assert "validation episodes" in (out / "table.md").read_text()
    # More validation episodes on a study whose run dirs are gone: one line, the record kept as it was.
    record = (out / "dqfd-s0.json").read_text()
    (out / "dqfd-s0" / "checkpoints" / "final.safetensors").rename(tmp_path / "final.safetensors")
    assert cli.main(["experiment", *argv, "--final-validation-episodes", "3"]) == 2
    assert "needs the run's final network" in capsys.readouterr().err
    assert (out / "dqfd-s0.json").read_text() == record
    (tmp_path / "final.safetensors").rename(out / "dqfd-s0" / "checkpoints" / "final.safetensors")
    # Other test episodes in the same --out: refused before anything runs, naming the difference.
    other = [("4" if a == "3" else a) for a in argv]
    assert cli.main(["experiment", *other]) == 2
    assert "is of another protocol (test" in capsys.readouterr().err


def test_a_finished_seed_is_published_before_the_next_seed_runs(tmp_path, monkeypatch, capsys):
    # The networks were once published at the study's end only: a later seed's stopped run left a
    # finished seed's network unpublished (and lost with a machine that was replaced).
    from laneshift.tools import cli
    from laneshift.tools.studies import protocol

    out, pub = tmp_path / "proto", tmp_path / "published"
    argv = ["experiment", "protocol", "--scenario", "straight", "--method", "dqfd", "--seeds", "0,1",
            "--env-steps", "400", "--test-episodes", "2", "--eval-max-steps", "30", "--validation-every", "0",
            "--out", str(out), "--publish", str(pub), *TINY]
    train = protocol.train_seed

    def seed_1_stopped(cfg, state, out_dir, method):
        if cfg.train.seed == 1:
            raise SystemExit("seed 1: stopped; the same command again continues it")
        train(cfg, state, out_dir, method)

    monkeypatch.setattr(protocol, "train_seed", seed_1_stopped)
    assert cli.main(argv) != 0
    assert "seed 1: stopped" in capsys.readouterr().err
    assert (pub / "straight-dqfd-seed0-final.safetensors").read_bytes() == \
        (out / "dqfd-s0" / "checkpoints" / "final.safetensors").read_bytes()
    doc = json.loads((pub / "straight-dqfd-seed0-final.json").read_text())
    assert doc["seed"] == 0 and doc["test"]["lanes"]["random"]["episodes"] == 2
    assert not (pub / "straight-dqfd-seed1-final.safetensors").exists() and not (out / "results.json").exists()


def test_a_held_test_drives_validation_episodes_only_until_the_same_command_without_it(tmp_path, monkeypatch, capsys):
    """A probe (``--hold-test``) trains and validates each seed and drives no test episode, so no
    test rate exists while its choice is open; the same command without it then drives the test
    episodes of the validated seed, training nothing."""
    from laneshift.tools import cli
    from laneshift.tools.studies import protocol

    out = tmp_path / "proto"
    argv = ["experiment", "protocol", "--scenario", "straight", "--method", "dqfd", "--seeds", "0",
            "--env-steps", "400", "--test-episodes", "2", "--eval-max-steps", "30", "--validation-every", "0",
            "--final-validation-episodes", "2", "--out", str(out), *TINY]
    driven, evaluate = [], protocol.evaluate_final

    def spied(greedy, env_cfg, episodes, episode_seed, label):
        driven.append(episode_seed)
        return evaluate(greedy, env_cfg, episodes, episode_seed, label)

    monkeypatch.setattr(protocol, "evaluate_final", spied)
    assert cli.main([*argv, "--hold-test"]) == 0
    printed = capsys.readouterr().out
    assert driven == [VALIDATION_SEED]  # the final network on validation episodes, never on the test's
    record = json.loads((out / "dqfd-s0.json").read_text())
    assert record["test_held"] is True and "eval" not in record
    assert record["final_validation"]["episode_seed"] == VALIDATION_SEED
    results = json.loads((out / "results.json").read_text())
    assert results["test_held"] is True and results["test"]["episode_seed"] == VALIDATION_SEED
    (run,) = results["methods"]["dqfd"]["runs"]
    assert run["eval"] == record["final_validation"]["eval"]
    assert results["baselines"]["scripted"]["random"]["survival"]["episodes"] == 2
    table = (out / "table.md").read_text()
    assert "**Test held**" in table and "100,000" not in table and "100,000" not in printed
    assert not (out / "baselines.json").exists() and (out / "baselines-validation.json").is_file()
    # Again with the test held: the validated seed is skipped, nothing is driven.
    assert cli.main([*argv, "--hold-test"]) == 0
    assert "seed 0: validated" in capsys.readouterr().out and driven == [VALIDATION_SEED]
    # The same command without it: the test episodes now, nothing trained again.
    log = (out / "dqfd-s0.log").read_text()
    assert cli.main(argv) == 0
    assert driven == [VALIDATION_SEED, 100_000] and (out / "dqfd-s0.log").read_text() == log
    tested = json.loads((out / "dqfd-s0.json").read_text())
    assert "test_held" not in tested and tested["eval"]["random"]["episodes"] == 2
    assert tested["final_validation"] == record["final_validation"]
    results = json.loads((out / "results.json").read_text())
    assert "test_held" not in results and results["test"]["episode_seed"] == 100_000
    assert results["final_validation"]["test"]["episode_seed"] == VALIDATION_SEED
    assert "**Test held**" not in (out / "table.md").read_text()
    # Judged again on fresh validation episodes (--final-validation-seed): those replace the kept ones, the
    # drivers' first set kept beside the new.
    fresh = VALIDATION_SEED + 1000
    assert cli.main([*argv, "--final-validation-seed", str(fresh)]) == 0
    assert driven == [VALIDATION_SEED, 100_000, fresh]
    assert json.loads((out / "dqfd-s0.json").read_text())["final_validation"]["episode_seed"] == fresh
    results = json.loads((out / "results.json").read_text())
    assert results["final_validation"]["test"]["episode_seed"] == fresh and results["test"]["episode_seed"] == 100_000
    assert f"seeds {fresh:,}-{fresh + 1:,}" in (out / "table.md").read_text()
    assert (out / f"baselines-validation-{fresh}.json").is_file() and (out / "baselines-validation.json").is_file()


def test_the_seed_bar_starts_at_the_share_a_stopped_run_made_before(tmp_path):
    """A resumed seed's remaining piece counts as what is left of it, not as a whole seed done fast."""
    from laneshift.config import load_run_config
    from laneshift.tools.studies.protocol import seeds_progress, started_shares

    configs, states = {}, {0: "done", 1: "resume", 2: "new", 3: "resume"}
    for seed in states:
        run_dir = tmp_path / f"s{seed}"
        run_dir.mkdir()
        configs[seed] = load_run_config(overrides={"train.run_dir": str(run_dir), "train.env_steps": 1200})
    records = [{"kind": "learner", "env_steps": 0, "phase": 1}, {"kind": "eval", "env_steps": 900},
               {"kind": "learner", "env_steps": 300, "phase": 2}]
    (tmp_path / "s1" / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    (tmp_path / "s2" / "metrics.jsonl").write_text(json.dumps(records[-1]) + "\n")  # new: not counted
    started = started_shares(configs, states)  # seed 3 stopped before its first record
    assert started == {1: 0.25}
    with seeds_progress(states, "protocol", started=started) as bar:
        assert bar.n == pytest.approx(1.25)  # seed 0 done, a quarter of seed 1
        bar.update(1 - started[1])
        assert bar.n == pytest.approx(2.0)


def test_bad_input_fails_before_any_run(tmp_path, capsys):
    from laneshift.tools import cli

    for argv, needle in ((["--method", "dqfq"], "--method: unknown 'dqfq'"), (["--seeds", "0,0"], "named twice"),
                         (["--set", "learner.lr=fast"], "learner.lr"), (["--road", "a/b"], "--road"),
                         (["--scenario", "allroads", "--set", "env.road=merge"], "leave env.road empty"),
                         (["--hold-test"], "give --final-validation-episodes"),
                         (["--final-validation-seed", "199999"], "seeded from 200,000 up"),
                         (["--hold-test", "--final-validation-episodes", "2", "--publish", str(tmp_path / "pub")],
                          "published with its test table")):
        assert cli.main(["experiment", "protocol", "--out", str(tmp_path / "p"), *argv]) == 2
        assert needle in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


def test_a_set_that_needs_the_methods_own_setting_is_accepted_and_refused_without_it(tmp_path, capsys):
    """A shield figure needs ``env.shield``: given with a shield method it is the method's run's
    setting; with a method without the shield it is one line, and nothing runs."""
    from laneshift.tools import cli
    from laneshift.tools.studies.protocol import plan

    figures = ["--set", "env.shield_gap=2.0", "--set", "env.shield_decel=1.0"]
    args = cli.build_parser().parse_args(["experiment", "protocol", "--out", str(tmp_path / "p"), "--method",
                                          "dqfd-bc-alongside-safe-shield", "--seeds", "0", *figures])
    configs = plan(args)[2]
    assert (configs[0].env.shield, configs[0].env.shield_gap, configs[0].env.shield_decel) == (True, 2.0, 1.0)
    assert cli.main(["experiment", "protocol", "--out", str(tmp_path / "q"), "--method", "dqfd-bc", *figures]) == 2
    assert "it needs env.shield=true" in capsys.readouterr().err
    assert not (tmp_path / "q").exists()


def test_the_four_roads_evaluations_pool_into_one():
    from laneshift.tools.studies.allroads import merge_evals

    a = {"episodes": 2, "return_mean": 1.0, "return_std": 0.0, "length_mean": 10.0, "survival_rate": 1.0,
         "achievement_rate": 0.5, "crashes": {}}
    b = {"episodes": 6, "return_mean": 5.0, "return_std": 2.0, "length_mean": 20.0, "survival_rate": 0.5,
         "achievement_rate": 0.5, "crashes": {"collision": {"start lane 1": 2}, "offroad": {"start lane 2": 1}}}
    c = {**b, "crashes": {"collision": {"start lane 1": 1, "start lane 0": 2}}}
    m = merge_evals([a, b, c])
    assert m["episodes"] == 14 and m["survival_rate"] == 8 / 14 and m["achievement_rate"] == 7 / 14
    assert m["length_mean"] == pytest.approx((20 + 120 + 120) / 14) and m["return_mean"] == pytest.approx(62 / 14)
    values = [1.0] * 2 + [3.0, 7.0] * 6  # 12 episodes of mean 5 and spread 2
    assert m["return_std"] == pytest.approx(float(np.std(values)))
    assert m["crashes"] == {"collision": {"start lane 1": 3, "start lane 0": 2}, "offroad": {"start lane 2": 1}}
    assert m["survival_ci95"][0] < 8 / 14 < m["survival_ci95"][1]


def test_protocol_on_allroads_tests_each_road_on_its_own_episodes(tmp_path, capsys):
    from laneshift.tools import cli
    from laneshift.actors.envs.demonstrator import ScriptedDriver
    from laneshift.config import EnvConfig
    from laneshift.tools.studies.evaluate import evaluate_lanes

    out, pub = tmp_path / "proto", tmp_path / "published"
    argv = ["experiment", "protocol", "--scenario", "allroads", "--method", "dqfd", "--seeds", "0",
            "--env-steps", "400", "--test-episodes", "2", "--eval-max-steps", "30", "--validation-every", "0",
            "--out", str(out), "--publish", str(pub), *TINY, "--set", "env.max_steps=50"]
    assert cli.main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    roads = ("straight", "merge", "curve", "roundabout")
    assert results["road"] == "allroads" and list(results["roads"]) == list(roads)
    assert results["test"] == {"episode_seed": 100_000, "episodes_per_lane": 2, "max_steps": 30, "roads": list(roads)}
    (run,) = results["methods"]["dqfd"]["runs"]
    for lane in ("random", "non-target"):
        assert run["eval"][lane]["episodes"] == 8  # the four roads pooled
        assert results["baselines"]["scripted"][lane]["survival"]["episodes"] == 8
        for road in roads:
            assert run["eval_by_road"][road][lane]["episodes"] == 2
            assert results["roads"][road]["methods"]["dqfd"][lane]["survival"]["per_seed"] == \
                [run["eval_by_road"][road][lane]["survival_rate"]]
            assert set(results["roads"][road]["target_met"][lane]) == {"survival", "achievement"}
    # A road's rows are that road's own test episodes: the scripted driver on the single-road scenario agrees.
    merge = evaluate_lanes(ScriptedDriver, EnvConfig(scenario="merge", max_steps=30), 2, 100_000)
    for lane in ("random", "non-target"):
        for metric in ("survival", "achievement"):
            assert results["roads"]["merge"]["baselines"]["scripted"][lane][metric]["rate"] == \
                merge[lane][f"{metric}_rate"]
    assert all((out / f"baselines-{road}.json").is_file() for road in roads)
    table = (out / "table.md").read_text()
    for road in (*roads, "all four"):
        for lane in ("random", "non-target"):
            assert f"| {road} | {lane} |" in table
    assert "target 95% / 90% met" in table and "Validation during training: off" in table
    # Published as allroads-<method>-seed<N>, with each road's `laneshift eval` commands.
    assert (pub / "allroads-dqfd-seed0-final.safetensors").is_file()
    doc = json.loads((pub / "allroads-dqfd-seed0-final.json").read_text())
    assert doc["test"]["lanes"]["random"]["episodes"] == 8 and list(doc["test"]["roads"]) == list(roads)
    entry = doc["test"]["roads"]["curve"]["non-target"]
    cmd = shlex.split(entry["command"])
    assert cmd[cmd.index("--scenario") + 1] == "allroads" and "env.road=curve" in cmd
    capsys.readouterr()
    assert cli.main(cmd[1:] + ["--json"]) == 0
    again = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (again["survival_rate"], again["achievement_rate"]) == (entry["survival_rate"], entry["achievement_rate"])
    # The same command again: the seed is done, each road's baselines are kept.
    assert cli.main(argv) == 0
    printed = capsys.readouterr().out
    assert "protocol: dqfd seed 0: done" in printed and printed.count("baselines: kept from") == 4
    assert json.loads((out / "results.json").read_text())["roads"] == results["roads"]
    # With the final networks' validation: each road's own validation episodes, as the test's.
    assert cli.main([*argv, "--final-validation-episodes", "2"]) == 0
    validated = json.loads((out / "results.json").read_text())["final_validation"]
    assert validated["test"]["episode_seed"] == VALIDATION_SEED and list(validated["roads"]) == list(roads)
    assert validated["roads"]["merge"]["baselines"]["scripted"]["random"]["survival"]["episodes"] == 2
    assert all((out / f"baselines-validation-{road}.json").is_file() for road in roads)
    assert "| roundabout | non-target |" in (out / "table.md").read_text().split("validation episodes")[1]
