"""Registration: ids, the "module:id" form in a fresh process, SCENARIOS and make_env.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import pytest

import laneshift.actors.envs as envs


def test_scenarios_and_ids() -> None:
    assert envs.SCENARIOS == {
        "straight": "laneshift/StraightLaneChange-v0",
        "merge": "laneshift/MergeLaneChange-v0",
        "curve": "laneshift/CurveLaneChange-v0",
        "roundabout": "laneshift/RoundaboutLaneChange-v0",
        "allroads": "laneshift/AllRoadsLaneChange-v0",
        "lka": "laneshift/LaneKeepingAssist-v0",
    }
    for env_id in envs.SCENARIOS.values():
        assert env_id in gym.registry
        assert envs.make_env(env_id).unwrapped.spec.id == env_id


@pytest.mark.parametrize("module", ["laneshift.actors.envs", "laneshift.actors"])
def test_module_id_form_in_a_fresh_process(module: str) -> None:
    code = (
        "import gymnasium as gym\n"
        f"for i in ('StraightLaneChange', 'LaneKeepingAssist'):\n"
        f"    env = gym.make('{module}:laneshift/' + i + '-v0', max_steps=5)\n"
        "    obs, info = env.reset(seed=0)\n"
        "    print(i, obs.shape, env.step(0)[1] is not None)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "StraightLaneChange (82,) True" in out.stdout and "LaneKeepingAssist (6,) True" in out.stdout
