"""LaneKeepingAssist-v0: the MATLAB plant, checked against an independent integration.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import laneshift.actors.envs  # noqa: F401  (registers the ids)
from laneshift.actors.envs.demonstrator import LKAExpert
from laneshift.actors.envs.lka import LKAParams, expm

P = LKAParams()


def _rhs(x: np.ndarray, u: float) -> np.ndarray:
    """The plant written out term by term (not via lka.continuous_model): x = [vy, r, e1, e2, ie1, ie2]."""
    m, Iz, lf, lr, Cf, Cr, Vx, rho = P.m, P.Iz, P.lf, P.lr, P.Cf, P.Cr, P.Vx, P.rho
    vy, r, e1, e2 = x[:4]
    dvy = -(2 * Cf + 2 * Cr) / (m * Vx) * vy + (-(2 * Cf * lf - 2 * Cr * lr) / (m * Vx) - Vx) * r + 2 * Cf / m * u
    dr = -(2 * Cf * lf - 2 * Cr * lr) / (Iz * Vx) * vy - (2 * Cf * lf**2 + 2 * Cr * lr**2) / (Iz * Vx) * r + 2 * Cf * lf / Iz * u
    return np.array([dvy, dr, vy + Vx * e2, r - Vx * rho, e1, e2])


def _rk4(x: np.ndarray, u: float, dt: float, n: int) -> np.ndarray:
    # RK4 with h = Ts/200 = 0.5 ms: |lambda| h < 0.003 for the fastest mode (~5.2 1/s), so the
    # global error (~ h^4) is ~1e-12, far inside the 1e-6 tolerance.
    h = dt / n
    for _ in range(n):
        k1 = _rhs(x, u)
        k2 = _rhs(x + h / 2 * k1, u)
        k3 = _rhs(x + h / 2 * k2, u)
        k4 = _rhs(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def test_trajectory_matches_independent_rk4() -> None:
    env = gym.make("laneshift/LaneKeepingAssist-v0", e1_limit=1e6)  # no termination: compare all 150 steps
    obs, _ = env.reset(seed=0, options={"e1": -0.4, "e2": 0.2})
    x = np.array([0.0, 0.0, -0.4, 0.2, 0.0, 0.0])
    actions = [int(15 + round(12 * np.sin(0.21 * k))) for k in range(150)]  # -12..12 degrees
    for a in actions:
        u = np.deg2rad(a - 15)
        x = _rk4(x, u, P.Ts, 200)
        obs, reward, terminated, truncated, info = env.step(a)
        de1, de2 = x[0] + P.Vx * x[3], x[1] - P.Vx * P.rho
        expected = np.array([x[2], x[3], de1, de2, x[4], x[5]])
        assert np.max(np.abs(env.unwrapped.state - x)) < 1e-6
        assert np.allclose(obs, expected, rtol=1e-6, atol=1e-6)  # float32 observation
    assert truncated and not terminated


def test_expm_against_closed_forms() -> None:
    t = 2.7
    rot = expm(np.array([[0.0, t], [-t, 0.0]]))
    assert np.allclose(rot, [[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]], atol=1e-13)
    a = np.array([[-3.0, 1.0], [0.0, -3.0]]) * 4.0  # large norm: exercises scaling and squaring
    assert np.allclose(expm(a), np.exp(-12.0) * np.array([[1.0, 4.0], [0.0, 1.0]]), rtol=1e-12, atol=1e-20)


def test_reset_ranges_and_options() -> None:
    env = gym.make("laneshift/LaneKeepingAssist-v0")
    e1s, e2s = [], []
    for seed in range(300):
        obs, _ = env.reset(seed=seed)
        e1s.append(obs[0])
        e2s.append(obs[1])
        assert np.all(env.unwrapped.state[[0, 1, 4, 5]] == 0.0)
    assert -0.5 <= min(e1s) < -0.4 and 0.4 < max(e1s) <= 0.5
    assert -0.1 <= min(e2s) < -0.08 and 0.08 < max(e2s) <= 0.1
    obs, _ = env.reset(options={"e1": -0.4, "e2": 0.2})
    assert obs[0] == pytest.approx(-0.4) and obs[1] == pytest.approx(0.2)
    obs = env.unwrapped.set_initial_state(0.3, -0.05)
    assert obs[0] == pytest.approx(0.3) and obs[1] == pytest.approx(-0.05)
    with pytest.raises(ValueError, match="options"):
        env.reset(options={"e3": 1.0})


def test_termination_when_lateral_deviation_exceeds_one_metre() -> None:
    env = gym.make("laneshift/LaneKeepingAssist-v0")
    env.reset(seed=1, options={"e1": 0.0, "e2": 0.0})
    prev = 0.0
    for _ in range(150):
        obs, _, terminated, truncated, info = env.step(30)  # +15 degrees all the time
        if terminated:
            break
        prev = obs[0]
    assert terminated and not truncated and info["crashed"]
    assert abs(obs[0]) > 1.0 and abs(prev) <= 1.0


def test_reward_formula_uses_previous_steering() -> None:
    env = gym.make("laneshift/LaneKeepingAssist-v0")
    env.reset(seed=2)
    for a in (0, 30, 7, 15, 22):
        obs, reward, *_, info = env.step(a)
        u = np.deg2rad(a - 15)
        e1, e2 = (float(v) for v in env.unwrapped.state[2:4])
        de1, de2 = env.unwrapped.derivatives()
        assert reward == pytest.approx(-(10 * e1**2 + 5 * e2**2 + 2 * u**2 + 5 * de1**2 + 5 * de2**2), rel=1e-9)
        assert sum(info["reward_terms"].values()) == pytest.approx(reward)


def test_bad_arguments_raise_value_error() -> None:
    with pytest.raises(ValueError, match="max_steps"):
        gym.make("laneshift/LaneKeepingAssist-v0", max_steps=0)
    env = gym.make("laneshift/LaneKeepingAssist-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(31)


def test_expert_centres_the_vehicle_like_the_matlab_example() -> None:
    env = gym.make("laneshift/LaneKeepingAssist-v0")
    obs, _ = env.reset(seed=0, options={"e1": -0.4, "e2": 0.2})
    expert = LKAExpert(env)
    e1 = []
    for _ in range(150):
        obs, _, terminated, truncated, _ = env.step(expert(obs))
        e1.append(obs[0])
        assert not terminated
    assert abs(e1[24]) < 0.05 and max(abs(v) for v in e1[30:]) < 0.02  # centred after ~2.5 s
