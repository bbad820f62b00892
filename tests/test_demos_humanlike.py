"""The human-like stand-in demonstrator: seeded, labelled as a stand-in, really delayed and noisy.

Few short episodes on the real straight scenario (vector observations), plus unit checks of the
delay / noise wrapper around a fake inner driver.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from laneshift.demos import load_shard
from laneshift.tools.demos.generate import generate_shard
from laneshift.tools.demos.cli import main
from laneshift.tools.demos.humanlike import (
    DEFAULT_ACTION_NOISE,
    DEFAULT_REACTION_STEPS,
    HumanLikeDriver,
    stand_in_label,
)
from laneshift.demos.outcomes import outcome_rates

KWARGS = {"observation": "vector", "max_steps": 30}


def _generate(out: Path, policy: str = "human-like", **extra) -> Path:
    return generate_shard(out, env_id_or_scenario="straight", env_kwargs=KWARGS, episodes=2,
                          seed=5, policy=policy, **extra)


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("humanlike")
    return {
        "scripted": _generate(root / "scripted", policy="scripted"),
        "human-like": _generate(root / "human-like"),
        "again": _generate(root / "again"),
    }


def test_same_command_same_sha256(shards: dict[str, Path]) -> None:
    first, again = load_shard(shards["human-like"]), load_shard(shards["again"])
    assert first.sha256 == again.sha256
    np.testing.assert_array_equal(first.actions, again.actions)


def test_metadata_says_it_is_a_stand_in(shards: dict[str, Path], capsys) -> None:
    meta = load_shard(shards["human-like"]).metadata
    label = stand_in_label(DEFAULT_REACTION_STEPS, DEFAULT_ACTION_NOISE)
    assert meta["recorded_by"] == label
    assert label.startswith("human-like stand-in") and label.endswith("not a person")
    assert f"reaction delay {DEFAULT_REACTION_STEPS} steps" in label
    assert meta["driver"] == "human-like" and meta["stand_in"] is True
    assert meta["reaction_steps"] == DEFAULT_REACTION_STEPS
    assert meta["action_noise"] == DEFAULT_ACTION_NOISE
    assert meta["reaction_delay_s"] == pytest.approx(DEFAULT_REACTION_STEPS / 10)  # 10 Hz policy
    assert meta["demonstrator"].endswith("demonstrator.ScriptedDriver")  # the expert it degrades
    assert "human-like" in meta["dataset_id"]

    assert main(["inspect", str(shards["human-like"]), "--png", str(shards["human-like"]) + ".png"]) == 0
    out = capsys.readouterr().out
    assert f"recorded by  {label}" in out and "NOT a person" in out

    scripted = load_shard(shards["scripted"]).metadata
    assert scripted["recorded_by"] == "scripted" and scripted["driver"] == "scripted"
    assert "stand_in" not in scripted and "reaction_steps" not in scripted


def test_it_drives_differently_from_the_scripted_driver(shards: dict[str, Path]) -> None:
    scripted, human_like = load_shard(shards["scripted"]), load_shard(shards["human-like"])
    assert scripted.metadata["seeds"] == human_like.metadata["seeds"] == [5, 6]
    # Same reset states (same seeds), different actions from the first steps on.
    np.testing.assert_array_equal(scripted.observations[0], human_like.observations[0])
    n = min(len(scripted), len(human_like))
    assert np.any(scripted.actions[:n] != human_like.actions[:n])
    assert scripted.sha256 != human_like.sha256


class Counter:
    """Fake inner driver: returns 0, 1, 2, ... (mod 9) on successive calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, obs=None) -> int:
        self.calls += 1
        return (self.calls - 1) % 9


def _drive(driver: HumanLikeDriver, steps: int) -> list[int]:
    return [driver(None) for _ in range(steps)]


@pytest.mark.parametrize("k", [0, 1, 3])
def test_reaction_delay_acts_on_the_decision_of_k_steps_ago(k: int) -> None:
    inner = Counter()
    actions = _drive(HumanLikeDriver(inner, 9, k, 0.0, np.random.default_rng(0)), 12)
    assert actions == [max(0, t - k) % 9 for t in range(12)]
    assert inner.calls == 12  # the inner driver still sees every step


def test_action_noise_replaces_a_share_p_with_uniform_actions() -> None:
    steps = 4000
    noisy = HumanLikeDriver(Counter(), 9, 0, 0.25, np.random.default_rng(1))
    actions = np.array(_drive(noisy, steps))
    changed = actions != np.arange(steps) % 9
    # A replacement equals the intended action 1 time in 9: 0.25 * 8/9 of the steps change.
    assert changed.mean() == pytest.approx(0.25 * 8 / 9, abs=0.03)
    assert noisy.noisy_steps == pytest.approx(0.25 * steps, rel=0.1)
    assert set(actions[changed]) == set(range(9))
    everything = np.array(_drive(HumanLikeDriver(Counter(), 9, 0, 1.0, np.random.default_rng(1)), 900))
    assert np.bincount(everything, minlength=9).min() > 60  # uniform over all 9 actions


def test_bad_parameters_are_refused(tmp_path: Path, capsys) -> None:
    with pytest.raises(ValueError, match="reaction_steps"):
        HumanLikeDriver(Counter(), 9, -1, 0.1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="action_noise"):
        _generate(tmp_path / "x", action_noise=1.5)
    with pytest.raises(ValueError, match="human-like"):
        _generate(tmp_path / "y", policy="scripted", reaction_steps=2)
    assert main(["generate", "--scenario", "straight", "--episodes", "1", "--out",
                 str(tmp_path / "z"), "--reaction-steps", "2"]) == 2
    assert "--driver human-like" in capsys.readouterr().err
    assert not (tmp_path / "z").exists()


def test_cli_generate_human_like(tmp_path: Path, capsys) -> None:
    out = tmp_path / "cli"
    assert main(["generate", "--scenario", "straight", "--episodes", "1", "--out", str(out),
                 "--max-steps", "15", "--driver", "human-like", "--reaction-steps", "2",
                 "--action-noise", "0.5"]) == 0
    printed = capsys.readouterr().out
    label = stand_in_label(2, 0.5)
    assert f"recorded by: {label}" in printed
    meta = load_shard(out).metadata
    assert meta["recorded_by"] == label and meta["reaction_steps"] == 2
    assert meta["action_noise"] == 0.5


def test_a_crash_on_the_target_lane_is_no_achievement() -> None:
    """The paper's achievement (in the target lane at step 300) needs the episode to survive."""
    rates = outcome_rates([{"crashed": True, "on_target_lane": True},
                           {"crashed": False, "on_target_lane": True},
                           {"crashed": False, "on_target_lane": False}])
    assert rates == {"survival_rate": pytest.approx(2 / 3), "achievement_rate": pytest.approx(1 / 3)}
