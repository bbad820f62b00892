"""env.frame_supersample: grayscale frames drawn at k times the resolution and block-averaged. The
frame keeps its shape and greys, a car's sub-pixel move shows in its edge pixels, the env refuses
a bad factor and the downsample is each block's rounded mean (the run config's side:
test_frame_options.py).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.actors.envs import make_env
from laneshift.actors.envs.rendering import GRAY_PALETTE, TopDownRenderer


def _frame(supersample: int, car_x: float) -> np.ndarray:
    """The straight road's view around (0, 0) with one car at (car_x, 0)."""
    env = make_env("straight", observation="grayscale").unwrapped
    renderer = TopDownRenderer(env.layout, (100, 100), 2.0, grayscale=True, supersample=supersample)
    y = float(env.layout.paths[1].position(np.array([100.0]), 0.0)[1][0])  # the middle lane's centre line
    npc = (np.array([100.0 + car_x]), np.array([y]), np.array([0.0]), "npc")
    return renderer.render((100.0, y), 2, [npc], 5.0, 2.0)


def test_a_supersampled_frame_keeps_its_shape_and_its_greys_on_average():
    plain, smooth = _frame(1, 0.0), _frame(4, 0.0)
    assert plain.shape == smooth.shape == (100, 100) and smooth.dtype == np.uint8
    assert set(np.unique(plain).tolist()) <= set(GRAY_PALETTE.values())  # whole-pixel polygons
    assert not set(np.unique(smooth).tolist()) <= set(GRAY_PALETTE.values())  # anti-aliased edges
    # The same scene, drawn finer (pygame fills a polygon's boundary pixels: whole-pixel shapes are a little larger).
    assert abs(float(plain.mean()) - float(smooth.mean())) < 0.1 * float(plain.mean())


def test_a_sub_pixel_move_shows_in_the_supersampled_frame():
    # 0.15 m is 0.3 px at 2 px/m: 1.2 drawn pixels at k = 4, so the car's edge pixels change grey.
    before, after = _frame(4, 0.0), _frame(4, 0.15)
    changed = np.argwhere(before != after)
    assert len(changed) > 0
    assert np.all(np.abs(changed[:, 1] - 50) <= 7)  # only around the car (5 m long: +-5 px)
    greys = set(np.unique(after[tuple(changed.T)]).tolist())
    assert greys - set(GRAY_PALETTE.values())  # partly covered pixels: in-between greys


def test_the_env_draws_supersampled_frames_and_refuses_a_bad_factor():
    env = make_env("straight", observation="grayscale", frame_supersample=2)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 100, 100) and obs.dtype == np.uint8
    obs, *_ = env.step(4)
    assert obs.shape == (4, 100, 100)
    with pytest.raises(ValueError, match="frame_supersample"):
        make_env("straight", observation="grayscale", frame_supersample=0)
    with pytest.raises(ValueError, match="supersample"):
        TopDownRenderer(env.unwrapped.layout, (100, 100), 2.0, grayscale=True, supersample=1.5)


@pytest.mark.parametrize("k", [2, 4, 8])
def test_the_downsample_is_each_blocks_rounded_mean(k):
    env = make_env("straight", observation="grayscale").unwrapped
    renderer = TopDownRenderer(env.layout, (10, 12), 2.0, grayscale=True, supersample=k)
    rng = np.random.default_rng(k)
    for drawn in (rng.integers(0, 256, (10 * k, 12 * k), dtype=np.uint8),
                  rng.integers(0, 256, (10 * k, 12 * k, 3), dtype=np.uint8)):
        blocks = drawn.reshape(10, k, 12, k, *drawn.shape[2:]).astype(np.float64)
        expected = np.floor(blocks.mean(axis=(1, 3)) + 0.5).astype(np.uint8)  # half up, as the code rounds
        np.testing.assert_array_equal(renderer._downsample(drawn), expected)
