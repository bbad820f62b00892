"""The across-seed statistics of the studies (``laneshift.tools.studies.stats``): the percentile bootstrap
over runs and curves on a common grid, on cases whose answer is known. Fast and deterministic (the
bootstrap is seeded). Room: tests, unit. May import: laneshift.tools.studies.stats, numpy, pytest.
"""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.tools.studies.stats import (bootstrap_ci, common_range, curves_on_grid, drop_noise_floor,
                                          paired_difference_ci)


def test_identical_runs_give_a_zero_width_interval_at_their_value():
    assert bootstrap_ci([0.3, 0.3, 0.3]) == (pytest.approx(0.3, abs=0), pytest.approx(0.3, abs=0))
    lo, hi = bootstrap_ci(np.tile([1.0, 2.0, 3.0], (4, 1)))  # four identical curves
    np.testing.assert_array_equal(lo, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(hi, [1.0, 2.0, 3.0])


def test_one_run_gives_its_value():
    assert bootstrap_ci([0.42]) == (0.42, 0.42)


def test_two_runs_0_and_1_cover_0_to_1():
    # Resampled means are 0, 0.5, 1 with probability 1/4, 1/2, 1/4: the 2.5 % and 97.5 % quantiles are 0 and 1.
    assert bootstrap_ci([0.0, 1.0]) == (0.0, 1.0)
    assert bootstrap_ci([0.07, 0.23]) == (pytest.approx(0.07), pytest.approx(0.23))


def test_interval_holds_the_mean_and_stays_within_the_runs():
    x = np.array([0.1, 0.5, 0.2, 0.9, 0.4])
    lo, hi = bootstrap_ci(x)
    assert x.min() <= lo < x.mean() < hi <= x.max()


def test_seeded_so_the_same_data_give_the_same_interval():
    x = np.random.default_rng(3).random(7)
    assert bootstrap_ci(x) == bootstrap_ci(x)
    assert bootstrap_ci(x, seed=1) != bootstrap_ci(x, seed=2)


def test_the_band_widens_when_the_seeds_disagree_more():
    rng = np.random.default_rng(0)
    base = rng.normal(size=8)
    widths = []
    for spread in (0.1, 0.5, 1.0, 3.0):
        lo, hi = bootstrap_ci(0.5 + spread * base)
        widths.append(hi - lo)
    assert widths == sorted(widths) and widths[0] < widths[-1]
    # Per point of a curve too: where the seeds are further apart, the band is wider.
    runs = np.stack([np.zeros(5) + s * np.arange(5) for s in (-1.0, 0.0, 1.0)])
    lo, hi = bootstrap_ci(runs)
    assert np.all(np.diff(hi - lo) > 0) and hi[0] - lo[0] == 0


def test_a_smaller_confidence_gives_a_narrower_interval():
    x = np.linspace(0, 1, 6)
    lo95, hi95 = bootstrap_ci(x)
    lo50, hi50 = bootstrap_ci(x, confidence=0.5)
    assert lo95 <= lo50 < hi50 <= hi95


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        bootstrap_ci([])
    with pytest.raises(ValueError):
        bootstrap_ci([0.1, 0.2], confidence=1.0)


def test_curves_go_on_the_range_every_seed_covers():
    # Seed a: steps 0..1000, seed b: steps 200..800 at other points; both straight lines.
    xa = np.linspace(0, 1000, 11)
    xb = np.array([200.0, 350.0, 500.0, 800.0])
    c = curves_on_grid([xa, xb], [xa / 1000, xb / 1000 + 0.2], points=7)
    np.testing.assert_allclose(c["x"], np.linspace(200, 800, 7))
    np.testing.assert_allclose(c["runs"][0], c["x"] / 1000)
    np.testing.assert_allclose(c["runs"][1], c["x"] / 1000 + 0.2)
    np.testing.assert_allclose(c["mean"], c["x"] / 1000 + 0.1)
    # Two seeds a constant 0.2 apart: the band is the two seeds' values at every point.
    np.testing.assert_allclose(c["lo"], c["runs"][0])
    np.testing.assert_allclose(c["hi"], c["runs"][1])


def test_identical_seeds_give_a_zero_width_band_on_the_grid():
    x = np.array([0.0, 10.0, 20.0])
    c = curves_on_grid([x, x + 0.0], [np.array([1.0, 3.0, 2.0])] * 2, points=5)
    np.testing.assert_allclose(c["mean"], [1.0, 2.0, 3.0, 2.5, 2.0])
    np.testing.assert_array_equal(c["lo"], c["mean"])
    np.testing.assert_array_equal(c["hi"], c["mean"])


def test_curves_that_share_no_range_give_nothing():
    assert common_range([np.array([0.0, 1.0]), np.array([2.0, 3.0])]) is None
    assert common_range([np.array([0.0, 1.0]), np.array([])]) is None
    c = curves_on_grid([np.array([0.0, 1.0]), np.array([2.0, 3.0])], [np.zeros(2), np.zeros(2)])
    assert len(c["x"]) == len(c["mean"]) == len(c["lo"]) == len(c["hi"]) == 0
    with pytest.raises(ValueError):
        curves_on_grid([np.zeros(3)], [np.zeros(2)])


def test_drop_noise_floor_of_a_constant_policy_shrinks_with_the_episodes_per_evaluation():
    few, many = drop_noise_floor(0.96, 20, 10, 0.93), drop_noise_floor(0.96, 200, 10, 0.93)
    # 20 episodes: one more failure is 5 points, so a policy that never changes still "drops" ~10.
    assert few["median"] == 0.1 and few["share_above_5_points"] > 0.7
    assert many["median"] < 0.05 and many["p90"] <= 0.06 and many["share_above_5_points"] < 0.2
    assert drop_noise_floor(1.0, 20, 10, 0.93) == {"median": 0.0, "p90": 0.0, "share_above_5_points": 0.0}
    assert drop_noise_floor(0.5, 20, 10, 0.99, draws=200) is None  # never reaches the target
    assert drop_noise_floor(0.96, 20, 10, 0.93) == few  # seeded


def test_paired_difference_of_equal_groups_is_centred_on_zero():
    rng = np.random.default_rng(1)
    outcomes = (rng.random((3, 400)) < 0.9).astype(float)
    lo, hi = paired_difference_ci(outcomes, outcomes, resamples=2000)
    assert lo < 0.0 < hi


def test_paired_difference_resolves_a_clear_lead_and_holds_its_mean():
    rng = np.random.default_rng(2)
    episodes_hard = rng.random(800) < 0.1  # the same hard episodes for both groups: paired
    nets = np.array([~episodes_hard | (rng.random(800) < 0.5) for _ in range(3)], dtype=float)
    driver = (~episodes_hard).astype(float)[None, :]
    lead = nets.mean() - driver.mean()
    lo, hi = paired_difference_ci(nets, driver, resamples=2000)
    assert 0.0 < lo < lead < hi


def test_paired_difference_widens_with_fewer_episodes():
    rng = np.random.default_rng(3)
    a = (rng.random((3, 800)) < 0.92).astype(float)
    b = (rng.random((3, 800)) < 0.90).astype(float)
    wide = np.subtract(*paired_difference_ci(a[:, :200], b[:, :200], resamples=2000))
    narrow = np.subtract(*paired_difference_ci(a, b, resamples=2000))
    assert abs(wide) > abs(narrow)


def test_paired_difference_refuses_groups_over_other_episodes():
    with pytest.raises(ValueError, match="same episodes"):
        paired_difference_ci(np.ones((3, 10)), np.ones((1, 9)))
