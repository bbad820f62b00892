"""``laneshift demos inspect`` / ``generate`` through the CLI's register() hook.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import h5py
import numpy as np
import pytest

from laneshift.demos import load_shard
from laneshift.tools.demos.generate import generate_shard
from laneshift.tools.demos.cli import env_kwargs_from_args, main, register
from laneshift.demos.shard import dataset_data_dir


class SteerBack:
    """Policy factory shaped like ScriptedDriver (LKA: steer against e1)."""

    def __init__(self, env: gym.Env) -> None:
        pass

    def __call__(self, obs: np.ndarray) -> int:
        return int(np.clip(round(15 - 40 * obs[0]), 0, 30))


@pytest.fixture(scope="module")
def shard_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "lka"
    return generate_shard(out, env_id_or_scenario="lka", env_kwargs={"max_steps": 30},
                          episodes=3, seed=0, policy=SteerBack)


def test_register_under_a_parent_parser() -> None:
    parser = argparse.ArgumentParser(prog="laneshift")
    demos = parser.add_subparsers(dest="command").add_parser("demos")
    register(demos.add_subparsers(dest="demos_command", required=True))
    args = parser.parse_args(["demos", "generate", "--scenario", "straight", "--episodes", "2",
                              "--out", "x", "--observation", "grayscale", "--max-steps", "50",
                              "--initial-lane", "1", "--env-kwarg", "reward_preset=5"])
    assert callable(args.func) and args.episodes == 2 and args.seed == 0
    assert env_kwargs_from_args(args) == {"observation": "grayscale", "max_steps": 50,
                                          "initial_lane": 1, "reward_preset": 5}
    # The option's own spelling gives the env the same number (it once passed the text "5", which the
    # env refused).
    args = parser.parse_args(["demos", "generate", "--scenario", "straight", "--episodes", "2", "--out", "x",
                              "--reward-preset", "5"])
    assert env_kwargs_from_args(args) == {"reward_preset": 5}
    args = parser.parse_args(["demos", "inspect", "some/dir"])
    assert callable(args.func) and args.shard == "some/dir"


def test_inspect_prints_summary_and_writes_png(shard_dir: Path, capsys) -> None:
    shard = load_shard(shard_dir)
    assert main(["inspect", str(shard_dir)]) == 0
    out = capsys.readouterr().out
    assert "episodes     3" in out and f"steps        {len(shard)}" in out
    assert "survival" in out and "achievement  n/a" in out  # LKA has no target lane
    png = shard_dir.with_name("lka_returns.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"return plot  {png}" in out


def test_inspect_json(shard_dir: Path, tmp_path: Path, capsys) -> None:
    png = tmp_path / "r.png"
    assert main(["inspect", str(shard_dir), "--png", str(png), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    shard = load_shard(shard_dir)
    returns = [float(shard.rewards[shard.episode_ids == e].astype(np.float64).sum())
               for e in range(3)]
    assert summary["episode_returns"] == pytest.approx(returns)
    assert summary["returns"]["mean"] == pytest.approx(np.mean(returns))
    assert summary["action_histogram"] == np.bincount(shard.actions, minlength=31).tolist()
    assert summary["steps"] == len(shard) and png.is_file()


def test_inspect_refuses_a_corrupted_shard(shard_dir: Path, tmp_path: Path, capsys) -> None:
    import shutil

    bad = shutil.copytree(shard_dir, tmp_path / "bad")
    with h5py.File(dataset_data_dir(bad) / "main_data.hdf5", "a") as f:
        f["episode_0/actions"][0] = (f["episode_0/actions"][0] + 1) % 31
    assert main(["inspect", str(bad)]) == 2
    assert "sha256 mismatch" in capsys.readouterr().err


def test_generate_refuses_existing_output(shard_dir: Path, capsys) -> None:
    assert main(["generate", "--scenario", "lka", "--episodes", "1", "--out", str(shard_dir)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err


def test_generate_achieved_only_says_what_it_left_out(tmp_path: Path, capsys) -> None:
    out = tmp_path / "achieved"
    assert main(["generate", "--scenario", "straight", "--episodes", "3", "--out", str(out), "--max-steps", "40",
                 "--achieved-only"]) == 0
    printed = capsys.readouterr().out
    assert "achievement 100.0 %" in printed and "more driven and left out" in printed
    assert main(["generate", "--scenario", "lka", "--episodes", "1", "--out", str(tmp_path / "lka"),
                 "--achieved-only"]) == 2
    assert "does not report" in capsys.readouterr().err


@pytest.mark.parametrize("observation, max_steps", [("vector", 40), ("grayscale", 12)])
def test_generate_straight_with_the_scripted_driver(tmp_path: Path, capsys, observation: str,
                                                    max_steps: int) -> None:
    """The CLI path end to end on the real straight scenario and ScriptedDriver."""
    from laneshift.actors.envs import make_env
    from laneshift.actors.envs.demonstrator import ScriptedDriver

    out = tmp_path / observation
    assert main(["generate", "--scenario", "straight", "--episodes", "2", "--out", str(out),
                 "--seed", "3", "--observation", observation, "--max-steps", str(max_steps)]) == 0
    assert "demonstrator survival" in capsys.readouterr().out
    shard = load_shard(out, env_id="laneshift/StraightLaneChange-v0", n_actions=9)
    meta = shard.metadata
    assert meta["env_kwargs"] == {"observation": observation, "max_steps": max_steps}
    assert meta["demonstrator"].endswith("demonstrator.ScriptedDriver")
    assert meta["obs_encoding"] == ("frame_stack" if observation == "grayscale" else "full")
    assert meta["survival_rate"] is not None and meta["achievement_rate"] is not None

    env = make_env("straight", observation=observation, max_steps=max_steps)
    env.action_space.seed(3)
    row = 0
    for episode, seed in enumerate([3, 4]):
        obs, _ = env.reset(seed=seed)
        driver, done = ScriptedDriver(env), False
        while not done:
            action = driver(obs)
            np.testing.assert_array_equal(shard.observations[row], obs)
            obs, reward, term, trunc, _ = env.step(action)
            assert (shard.actions[row], shard.rewards[row], shard.episode_ids[row]) == \
                (action, np.float32(reward), episode)
            np.testing.assert_array_equal(shard.next_observations[row], obs)
            done, row = term or trunc, row + 1
    assert row == len(shard)
