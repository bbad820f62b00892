"""The LKA protocol (``laneshift experiment lka``) end to end at a tiny budget: a real training run
on the LKA plant, its final network on the test episodes and the response test, the LQR expert on
the same ones, the table, the published network whose ``laneshift eval`` command gives the same
numbers, and a second invocation that skips the finished seed.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import json
import shlex

from laneshift.config import load_run_config, method_settings


def test_the_lka_recipe_is_a_method_without_demonstrations():
    cfg = load_run_config(overrides={**method_settings("matlab-dqn"), "env.scenario": "lka"})
    assert cfg.replay.demo_mode == "none" and cfg.learner.lr == 1e-3
    assert (cfg.replay.min_size, cfg.replay.samples_per_insert) == (1000, 64.0)


def test_lka_protocol_trains_tests_publishes_and_skips_a_finished_seed(tmp_path, capsys, monkeypatch):
    from laneshift.tools import cli

    out, pub = tmp_path / "lka", tmp_path / "published"
    argv = ["experiment", "lka", "--seeds", "0", "--env-steps", "1500", "--test-episodes", "3",
            "--out", str(out), "--publish", str(pub), "--set", "replay.min_size=200", "--set", "learner.hidden=32"]
    assert cli.main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    (run,) = results["runs"]
    assert run["method"] == "matlab-dqn" and run["eval"]["episodes"] == 3 and run["test"]["episode_seed"] == 100_000
    assert set(run["response"]) >= {"centred_after_s", "steering_settled_after_s", "steering_chatter_deg"}
    assert (out / "matlab-dqn-s0.lka_response.png").is_file() and (out / "expert.lka_response.png").is_file()
    # The LQR expert on the same episodes: it centres the car (MATLAB: within about 2.5 s).
    expert = results["expert"]
    assert expert["eval"]["episodes"] == 3 and expert["eval"]["survival_rate"] == 1.0
    assert expert["response"]["centred_after_s"] is not None and expert["response"]["centred_after_s"] < 2.5
    table = (out / "table.md").read_text()
    assert "| seed 0 |" in table and "| LQR expert |" in table
    # The published network, with its provenance; its `laneshift eval` command gives the same numbers.
    assert (pub / "lka-matlab-dqn-seed0-final.safetensors").read_bytes() == \
        (out / "matlab-dqn-s0" / "checkpoints" / "final.safetensors").read_bytes()
    doc = json.loads((pub / "lka-matlab-dqn-seed0-final.json").read_text())
    assert len(doc["git"]["revision"]) == 40 and doc["config"]["env"]["scenario"] == "lka"
    capsys.readouterr()
    assert cli.main(shlex.split(doc["test"]["command"])[1:] + ["--json", "--png", str(tmp_path / "r.png")]) == 0
    again = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (again["return_mean"], again["survival_rate"]) == (doc["test"]["return_mean"], doc["test"]["survival_rate"])
    assert again["lka_response"]["steering_chatter_deg"] == doc["test"]["response"]["steering_chatter_deg"]
    # The same command again: the seed is done; nothing trains.
    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")  # every bar line, at once
    assert cli.main(argv) == 0
    printed, bars = capsys.readouterr()
    assert f"lka: matlab-dqn seed 0: done ({out / 'matlab-dqn-s0.json'}), skipped" in printed
    # The seed done before is where the bar starts, not a seed done now in no time (no rate, no time left).
    assert "lka protocol matlab-dqn: 1/1 seed (100 %)" in bars and "?seed/s" in bars
    assert json.loads((out / "results.json").read_text())["runs"] == [run]
    # Another budget in the same --out: refused before anything runs, naming the difference.
    other = [("2000" if a == "1500" else a) for a in argv]
    assert cli.main(other) == 2
    assert "is of another protocol (env_steps 1500 there, 2000 now)" in capsys.readouterr().err


def test_lka_protocol_refuses_another_plant_and_bad_seeds_before_any_run(tmp_path, capsys):
    from laneshift.tools import cli

    for extra, needle in ((["--set", "env.scenario=straight"], "runs on the lka plant"),
                          (["--seeds", "1,1"], "named twice"), (["--method", "dqfq"], "--method: unknown")):
        assert cli.main(["experiment", "lka", "--out", str(tmp_path / "l"), *extra]) == 2
        assert needle in capsys.readouterr().err
    assert not (tmp_path / "l").exists()
