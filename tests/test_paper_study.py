"""The paper's question as a study (``laneshift experiment paper``): its answer, the interval of a
difference and retention's decline after a peak on hand-made results; every mode on the same
learner; one tiny real study end to end (two modes, one seed) whose second invocation trains nothing.

Room: tests, system for the end-to-end case (real Ray, zenoh or laneshift processes; the `system`
marker). May import: laneshift (any floor), pytest, numpy, the standard library."""

from __future__ import annotations

import json
import time

import pytest

from laneshift.config import METHODS, load_run_config, method_settings
from laneshift.tools.studies.paper import (MODES, answer, demo_episodes_needed, difference_ci, peak_decline,
                                     render_table)


def _run(seed: int, achievement: dict[str, float], curve: list[float]) -> dict:
    return {"seed": seed, "eval": {lane: {"episodes": 200, "survival_rate": min(1.0, a + 0.05), "achievement_rate": a}
                                   for lane, a in achievement.items()},
            "validation": {"curve": [{"env_steps": 1000 * (i + 1), "achievement_rate": v} for i, v in enumerate(curve)]}}


def _results(per_mode: dict[str, list[dict]]) -> dict:
    test = {"episode_seed": 100_000, "episodes_per_lane": 200, "max_steps": 300}
    lanes = {lane: {"survival": {"rate": 0.6}, "achievement": {"rate": 0.5}} for lane in ("random", "non-target")}
    return {"scenario": "straight", "demonstrator": "human-like", "demo_episodes": 450, "env_steps": 150_000,
            "seeds": [0, 1, 2], "modes": {m: {"method": MODES[m], "test": test, "runs": runs} for m, runs in per_mode.items()},
            "baselines": {"scripted": lanes, "human-like stand-in": lanes}}


def test_every_mode_runs_on_the_same_learner_and_differs_only_in_how_it_gives_demos():
    learner_keys = ("learner.n_step", "learner.dueling", "replay.capacity", "learner.lr_final", "learner.ema_decay",
                    "actor.epsilon_final")
    cfgs = {m: load_run_config(overrides=method_settings(p)) for m, p in MODES.items()}
    for key in learner_keys:
        section, name = key.split(".")
        assert len({getattr(getattr(c, section), name) for c in cfgs.values()}) == 1, key
    assert {m: c.replay.demo_mode for m, c in cfgs.items()} == {"none": "none", "retention": "retention",
                                                                "rehearsal": "rehearsal", "dqfd": "dqfd"}
    # The paper's retention keeps 10 % of the buffer; rehearsal pre-trains as long as dqfd does.
    assert cfgs["retention"].replay.demo_ratio == 0.1
    assert cfgs["rehearsal"].learner.phase1_updates == cfgs["dqfd"].learner.phase1_updates == 20_000
    assert all(p in METHODS for p in MODES.values())


def test_the_shard_is_sized_for_the_largest_demo_region_at_the_scenarios_episode_length():
    cfgs = [load_run_config(overrides={**method_settings(p), "env.max_steps": 300}) for p in MODES.values()]
    # dqfd keeps 30 % of 300,000 items: 90,000 transitions, 1.5x that in 300-step episodes.
    assert demo_episodes_needed(cfgs, 0) == 450
    assert demo_episodes_needed(cfgs, 7) == 7


def test_the_interval_of_a_difference_and_the_decline_after_a_peak():
    lo, hi = difference_ci([0.9, 0.92, 0.94], [0.5, 0.52, 0.54])
    assert 0.36 <= lo <= 0.4 <= hi <= 0.44
    lo, hi = difference_ci([0.9, 0.1], [0.5, 0.5])
    assert lo < 0 < hi
    assert peak_decline([{"env_steps": 1, "achievement_rate": 0.3}]) is None
    fall = peak_decline([{"env_steps": s, "achievement_rate": v} for s, v in ((1, 0.2), (2, 0.8), (3, 0.5))])
    assert fall == {"best": 0.8, "best_at": 2, "last": 0.5, "decline": pytest.approx(0.3)}


def test_the_answer_names_the_winner_its_margin_and_retentions_decline():
    results = _results({
        "none": [_run(s, {"random": 0.4 + s / 100, "non-target": 0.3}, [0.1, 0.3, 0.4]) for s in range(3)],
        "retention": [_run(s, {"random": 0.5, "non-target": 0.3}, [0.2, 0.7, 0.45]) for s in range(3)],
        "rehearsal": [_run(s, {"random": 0.9 - s / 100, "non-target": 0.3}, [0.5, 0.8, 0.9]) for s in range(3)]})
    lines = answer(results)
    assert lines[0].startswith("- **random initial lane**: rehearsal wins with 89.0% achievement, 39.0 points "
                               "above retention (50.0%)") and "excludes 0" in lines[0]
    assert "no winner" in lines[1] and "tie at 30.0%" in lines[1]  # all three equal from a non-target lane
    assert "Retention's decline after a peak" in lines[2] and "25.0 points on average" in lines[2]
    table = render_table(results)
    assert "| rehearsal (rehearsal-anneal) | random | 94.0% [" in table and "| 67 / 66 |" in table
    assert "| human-like stand-in (driver) | random | 60.0% | 50.0% | - | 50.7 / 50.3" in table


def test_bad_modes_fail_before_anything_runs(tmp_path, capsys):
    from laneshift.tools import cli

    assert cli.main(["experiment", "paper", "--modes", "none,dqfq", "--out", str(tmp_path / "p")]) == 2
    assert "--modes" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()


@pytest.mark.system
def test_a_tiny_study_trains_every_mode_answers_and_a_second_run_trains_nothing(tmp_path, capsys):
    from laneshift.tools import cli

    out = tmp_path / "paper"
    argv = ["experiment", "paper", "--modes", "none,rehearsal", "--seeds", "0", "--env-steps", "1200",
            "--demo-episodes", "6", "--test-episodes", "2", "--eval-max-steps", "30", "--validation-every", "600",
            "--validation-episodes", "1", "--demonstrator", "human-like", "--out", str(out),
            "--set", "replay.capacity=2000", "--set", "replay.min_size=200", "--set", "learner.hidden=32",
            "--set", "learner.batch_size=32", "--set", "replay.spi_tolerance=1024",
            "--set", "learner.phase1_updates=50", "--set", "env.max_steps=40"]
    assert cli.main(argv) == 0
    results = json.loads((out / "results.json").read_text())
    assert list(results["modes"]) == ["none", "rehearsal"] and results["demonstrator"] == "human-like"
    shard = out / "demos" / "straight-human-like-6ep"
    assert results["demo_shard"] == str(shard) and any(shard.glob("**/metadata.json"))
    # rehearsal learned from the study's shard; none had no demos.
    rehearsal = json.loads((out / "rehearsal" / "rehearsal-anneal-s0.json").read_text())
    assert rehearsal["config"]["replay"]["demo_paths"] == [str(shard)]
    none = json.loads((out / "none" / "none-anneal-s0.json").read_text())
    assert none["config"]["replay"]["demo_paths"] == [] and none["config"]["learner"]["n_step"] == 10
    table = (out / "table.md").read_text()
    assert "**The answer**" in table and "| none (none-anneal) | non-target |" in table
    assert (out / "curves_episodes.png").is_file() and (out / "episodes.json").is_file()
    # The modes share one test set, so the drivers drove it once, for the study.
    assert (out / "baselines.json").is_file()
    assert not (out / "none" / "baselines.json").exists() and not (out / "rehearsal" / "baselines.json").exists()
    first = capsys.readouterr().out
    assert first.count("protocol: baselines: kept from") == 1
    capsys.readouterr()
    began = time.monotonic()
    assert cli.main(argv) == 0  # everything done: read back, nothing trained or driven again
    printed = capsys.readouterr().out
    assert "demo shard kept from" in printed and "rehearsal-anneal seed 0: done" in printed
    assert time.monotonic() - began < 30
