"""env.frame_interval: the stacked grayscale frames lie k policy steps apart (t, t-k, t-2k, ...).
The stack keeps its shape, k = 1 is the last frames as before, a frame reappears k steps later one
slot further back, and the env refuses a bad interval (the run config's side: test_frame_options.py).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.actors.envs import make_env


def _observations(interval: int, steps: int) -> list[np.ndarray]:
    env = make_env("straight", observation="grayscale", frame_interval=interval)
    obs, _ = env.reset(seed=3)
    out = [obs]
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(4)  # keep speed and heading
        assert not (terminated or truncated)
        out.append(obs)
    return out


def test_the_stack_holds_frames_k_steps_apart_and_k_1_is_the_last_frames():
    k, n = 3, 12
    spaced, plain = _observations(k, n), _observations(1, n)
    assert all(o.shape == (4, 100, 100) and o.dtype == np.uint8 for o in spaced)
    # The same seed and actions draw the same newest frame whatever the interval.
    for a, b in zip(spaced, plain):
        np.testing.assert_array_equal(a[-1], b[-1])
    # k = 1: slot i of step t is the newest frame of step t - (3 - i).
    for t in range(3, n + 1):
        for i in range(4):
            np.testing.assert_array_equal(plain[t][i], plain[t - (3 - i)][-1])
    # k = 3: slot i of step t is the newest frame of step t - 3 (3 - i); before the episode, its first frame.
    for t in range(n + 1):
        for i in range(4):
            np.testing.assert_array_equal(spaced[t][i], spaced[max(0, t - k * (3 - i))][-1])
    # The traffic moves: frames 9 steps apart differ (the point of spacing them).
    assert not np.array_equal(spaced[n][0], spaced[n][-1])


def test_the_env_refuses_a_bad_interval():
    for bad in (0, 31, 1.5):
        with pytest.raises(ValueError, match="frame_interval"):
            make_env("straight", observation="grayscale", frame_interval=bad)


