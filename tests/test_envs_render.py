"""Grayscale observation: real, non-blank frames centred on the ego vehicle, target lane visible.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from laneshift.actors.envs import make_env
from laneshift.actors.envs.rendering import GRAY_PALETTE

LANE_CHANGE = ["straight", "merge", "curve", "roundabout"]


@pytest.mark.parametrize("scenario", LANE_CHANGE)
def test_frames_are_real_and_centred_on_the_ego_vehicle(scenario: str) -> None:
    env = make_env(scenario, observation="grayscale", policy_vehicles=1)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 100, 100) and obs.dtype == np.uint8
    for _ in range(12):
        obs, *_ = env.step(0)
    frame = obs[-1]
    values = set(np.unique(frame).tolist())
    assert {GRAY_PALETTE["offroad"], GRAY_PALETTE["lane"], GRAY_PALETTE["ego"]} <= values  # not blank
    ego = np.argwhere(frame == GRAY_PALETTE["ego"])
    assert frame[50, 50] == GRAY_PALETTE["ego"]
    assert np.allclose(ego.mean(axis=0), [49.5, 49.5], atol=1.0)  # centroid at the image centre
    assert 20 <= len(ego) <= 60  # a 5 m x 2 m car at 2 px/m (+ rasterisation)
    # The target lane is painted in its own grey and visible in the crop.
    assert (frame == GRAY_PALETTE["target"]).sum() > 100 or env.unwrapped.target_lane != env.unwrapped.ego.loc.lane
    assert not np.array_equal(obs[0], obs[-1])  # frames move: the stack holds 4 different frames


def test_target_lane_is_visible_from_the_next_lane() -> None:
    env = make_env("straight", observation="grayscale", initial_lane=1)
    obs, _ = env.reset(seed=0)
    frame = obs[-1]
    rows = np.flatnonzero((frame == GRAY_PALETTE["target"]).any(axis=1))
    assert rows.size >= 6 and rows.max() < 50  # lane 0 lies above the ego lane (world -y)


def test_observation_shape_as_list_and_first_stack() -> None:
    env = make_env("curve", observation="grayscale", observation_shape=[64, 80], stack_size=3)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (3, 64, 80) and env.observation_space.shape == (3, 64, 80)
    assert np.array_equal(obs[0], obs[-1])  # the first frame fills the stack
    assert obs[-1][32, 40] == GRAY_PALETTE["ego"]


def test_rgb_render() -> None:
    env = make_env("roundabout", render_mode="rgb_array", policy_vehicles=2)
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (300, 600, 3) and img.dtype == np.uint8 and len(np.unique(img.reshape(-1, 3), axis=0)) >= 4


def test_frames_are_real_with_sdl_dummy_driver() -> None:
    code = (
        "import numpy as np; from laneshift.actors.envs import make_env; "
        "env = make_env('straight', observation='grayscale'); obs, _ = env.reset(seed=0); "
        "print(len(np.unique(obs[-1])), int(obs[-1][50, 50]))"
    )
    env = dict(os.environ, SDL_VIDEODRIVER="dummy")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120, check=True)
    n_values, centre = map(int, out.stdout.split()[-2:])
    assert n_values >= 4 and centre == GRAY_PALETTE["ego"]


def test_the_renderer_loads_pygames_lazy_surfarray_at_import():
    """pygame-ce's surfarray is a LazyLoader module, not thread-safe before Python 3.12: two
    in-process workers drawing their first frame at once saw it half-loaded and one died
    ("no attribute 'pixels_red'", 5 of 13 runs of tests/test_inprocess.py). Importing the renderer
    must leave it fully loaded, before any thread draws. A fresh interpreter: nothing else loads it."""
    code = ("import types, pygame, laneshift.actors.envs.rendering\n"
            "print(type(pygame.surfarray) is types.ModuleType, hasattr(pygame.surfarray, 'pixels_red'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["True", "True"], out.stdout + out.stderr
