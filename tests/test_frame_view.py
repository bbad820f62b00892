"""The grayscale frame's view of the road: env.frame_centering, where the ego sits across the frame's
width (0.5 centred; highway-env's observations use 0.3, more of the road ahead in view), and
env.frame_scale, its pixels per metre (2: the 100 x 100 frame shows 50 m of road; 1: 100 m). The frame
keeps its shape, the ego is drawn where asked, a car is drawn as many pixels from the ego as the scale
makes its distance, a car 35 m ahead comes into view only off-centre and one 40 m ahead only at 1 px/m,
and the env and the renderer refuse a bad place or scale (the run config's side: test_frame_options.py).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.actors.envs import make_env
from laneshift.actors.envs.rendering import GRAY_PALETTE, TopDownRenderer


def _frame(centering: float, car_x: float, scale: float = 2.0) -> np.ndarray:
    """The straight road's view around an ego at (100, lane 1) with one car car_x metres ahead of it."""
    env = make_env("straight", observation="grayscale").unwrapped
    renderer = TopDownRenderer(env.layout, (100, 100), scale, grayscale=True, centering=centering)
    y = float(env.layout.paths[1].position(np.array([100.0]), 0.0)[1][0])  # the middle lane's centre line
    ego = (np.array([100.0]), np.array([y]), np.array([0.0]), "ego")
    npc = (np.array([100.0 + car_x]), np.array([y]), np.array([0.0]), "npc")
    return renderer.render((100.0, y), 2, [npc, ego], 5.0, 2.0)


def _columns(frame: np.ndarray, key: str) -> np.ndarray:
    return np.flatnonzero((frame == GRAY_PALETTE[key]).any(axis=0))


@pytest.mark.parametrize("centering", [0.5, 0.3, 0.2])
def test_the_ego_is_drawn_at_its_place_across_the_width(centering):
    frame = _frame(centering, 35.0)
    assert frame.shape == (100, 100) and frame.dtype == np.uint8
    ego = _columns(frame, "ego")
    assert abs(float(ego.mean()) - 100 * centering) <= 1.0  # 5 m long at 2 px/m: 10 columns around its place


def test_a_car_35_m_ahead_is_in_view_only_off_centre():
    # Centred, the view reaches 25 m ahead; at 0.3 it reaches 35 m, so the car's rear (32.5 m) shows.
    assert _columns(_frame(0.5, 35.0), "npc").size == 0
    assert _columns(_frame(0.3, 35.0), "npc").size > 0


def test_the_env_draws_off_centre_frames_and_refuses_a_bad_place():
    env = make_env("straight", observation="grayscale", frame_centering=0.3)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 100, 100)
    assert abs(float(np.flatnonzero((obs[-1] == GRAY_PALETTE["ego"]).any(axis=0)).mean()) - 30) <= 1.5
    for bad in (0.0, 1.0, -0.2):
        with pytest.raises(ValueError, match="frame_centering"):
            make_env("straight", observation="grayscale", frame_centering=bad)
    with pytest.raises(ValueError, match="centering"):
        TopDownRenderer(env.unwrapped.layout, (100, 100), 2.0, grayscale=True, centering=1.5)


@pytest.mark.parametrize("scale", [1.0, 2.0, 3.0])
def test_cars_are_drawn_at_the_scale(scale):
    frame = _frame(0.5, 12.0, scale)
    ego, npc = _columns(frame, "ego"), _columns(frame, "npc")
    assert abs(ego.size - 5 * scale) <= 1.5  # a 5 m car
    assert abs(float(npc.mean() - ego.mean()) - 12.0 * scale) <= 1.5


def test_a_car_40_m_ahead_is_in_view_only_at_one_pixel_a_metre():
    assert _columns(_frame(0.5, 40.0, 2.0), "npc").size == 0  # 25 m ahead in view
    assert _columns(_frame(0.5, 40.0, 1.0), "npc").size > 0  # 50 m ahead in view


def test_the_env_draws_at_its_scale_and_refuses_one_out_of_range():
    env = make_env("straight", observation="grayscale", frame_scale=1.0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 100, 100) and obs.dtype == np.uint8
    assert abs(np.flatnonzero((obs[-1] == GRAY_PALETTE["ego"]).any(axis=0)).size - 5) <= 1.5
    for bad in (0.4, 8.5, "wide"):
        with pytest.raises(ValueError, match="frame_scale"):
            make_env("straight", observation="grayscale", frame_scale=bad)
