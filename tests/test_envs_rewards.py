"""Reward presets (Table 1): the pure function and constructed situations in the env.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import laneshift.actors.envs as envs
from laneshift.actors.envs import REWARD_PRESETS, compute_reward

# Table 1: (collision, forward, stopped, target, non-target, epsilon final)
TABLE_1 = {
    1: (-10, 0.5, -0.5, 1.5, -1, 0.3),
    2: (-10, 0.5, -1.5, 1.0, -1, 0.3),
    3: (-10, 0.5, -1.5, 1.0, -1, 0.1),
    4: (-10, 0.0, -0.5, 1.5, -1, 0.1),
    5: (-5, 1.0, -1.0, 1.0, -2, 0.1),
}


@pytest.mark.parametrize("cond", sorted(TABLE_1))
def test_presets_are_table_1(cond: int) -> None:
    col, fwd, stop, tgt, non, eps = TABLE_1[cond]
    p = REWARD_PRESETS[cond]
    assert (p.collision, p.forward, p.stopped, p.target_lane, p.non_target_lane) == (col, fwd, stop, tgt, non)
    assert (p.epsilon_initial, p.epsilon_final) == (1.0, eps)


@pytest.mark.parametrize("cond", sorted(TABLE_1))
def test_pure_reward_function(cond: int) -> None:
    col, fwd, stop, tgt, non, _ = TABLE_1[cond]
    r, terms = compute_reward(cond, crashed=True, moving_forward=True, stopped=False, on_target_lane=True)
    assert r == col and terms["collision"] == col and sum(terms.values()) == r
    r, _ = compute_reward(cond, crashed=False, moving_forward=True, stopped=False, on_target_lane=True)
    assert r == pytest.approx(fwd + tgt)
    r, _ = compute_reward(cond, crashed=False, moving_forward=True, stopped=False, on_target_lane=False)
    assert r == pytest.approx(fwd + non)
    r, terms = compute_reward(cond, crashed=False, moving_forward=False, stopped=True, on_target_lane=False)
    assert r == pytest.approx(stop + non) and terms["stopped"] == stop
    with pytest.raises(ValueError, match="reward_preset"):
        compute_reward(6, crashed=False, moving_forward=False, stopped=False, on_target_lane=False)


def _env(cond: int, lane: int) -> gym.Env:
    env = gym.make(envs.SCENARIOS["straight"], reward_preset=cond, initial_lane=lane)
    env.reset(seed=7)
    return env


@pytest.mark.parametrize("cond", sorted(TABLE_1))
def test_constructed_situations_in_env(cond: int) -> None:
    col, fwd, stop, tgt, non, _ = TABLE_1[cond]
    keep = envs.paper_action_index(speed=0, turn=0)
    slower = envs.paper_action_index(speed=-1, turn=0)

    env = _env(cond, lane=0)  # target lane of the straight scenario
    _, r, term, _, info = env.step(keep)
    assert not term and info["on_target_lane"] and r == pytest.approx(fwd + tgt)
    assert info["reward_terms"]["target_lane"] == tgt

    env = _env(cond, lane=2)
    _, r, term, _, info = env.step(keep)
    assert not term and not info["on_target_lane"] and r == pytest.approx(fwd + non)

    env = _env(cond, lane=1)  # stopped (speed 0, braking keeps it at 0)
    env.unwrapped.ego.speed = 0.0
    _, r, term, _, info = env.step(slower)
    assert not term and info["speed"] == 0.0 and r == pytest.approx(stop + non)

    env = _env(cond, lane=0)  # off road: 3 m beyond the left edge of lane 0
    env.unwrapped.ego.position[1] = -5.0
    _, r, term, _, info = env.step(keep)
    assert term and info["crashed"] and info["offroad"] and not info["collided"] and r == col

    env = _env(cond, lane=1)  # collision: move a vehicle of the ego lane onto the ego vehicle
    u = env.unwrapped
    j = int(np.flatnonzero(u.traffic.lane == 1)[0])
    u.traffic.q[j] = u.ego.loc.s[1] + u.ego.speed / u.policy_frequency
    _, r, term, _, info = env.step(keep)
    assert term and info["crashed"] and info["collided"] and r == col


def test_motion_definitions() -> None:
    from laneshift.actors.envs.rewards import motion_flags

    assert motion_flags(0.4, 0.4) == (False, True)
    assert motion_flags(0.6, 0.6) == (True, False)
    assert motion_flags(2.0, 2.0 * math.cos(1.4)) == (False, False)  # mostly sideways: neither
