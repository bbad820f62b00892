"""The vector observation's gap features (``env.gap_features``): the middle of the nearest gap
long enough to merge into, per side, by the scripted driver's rule; their place in the layout, the
merge ramp's S-curve, the config's checks and the checkpoint's record.

Room: tests, unit. May import: laneshift (any floor), numpy, pytest, the standard library.
"""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.actors.envs import make_env
from laneshift.actors.envs.observations import (
    ALONGSIDE_FEATURES, EGO_FEATURES, LANE_FEATURES, LANE_SLOTS, MERGE_GAP, nearest_gap_middle, vector_size,
)

GAPS_AT = len(EGO_FEATURES) + len(LANE_SLOTS) * (len(LANE_FEATURES) + len(ALONGSIDE_FEATURES))


@pytest.mark.parametrize("cars, middle", [
    ([], 0.0),  # an empty lane: level with a gap already
    ([-10.0, 10.0], 0.0),  # exactly long enough
    ([-5.0, 5.0], -15.0),  # too short: the open lane behind the last car (ahead ties, behind first)
    ([-30.0, -5.0, 12.0, 40.0], -17.5),  # 25 m behind beats 28 m ahead, 17 m around the ego is short
    ([3.0], -7.0),  # one car just ahead: room behind it
])
def test_the_nearest_gap_by_the_drivers_rule(cars, middle):
    assert MERGE_GAP == 20.0
    assert nearest_gap_middle(np.array(cars), MERGE_GAP) == pytest.approx(middle)


def test_four_floats_after_the_alongside_block():
    plain = make_env("straight", alongside_features=True)
    gaps = make_env("straight", alongside_features=True, gap_features=True)
    assert gaps.observation_space.shape[0] == plain.observation_space.shape[0] + 4 == vector_size(8, True, True, True)
    a, _ = plain.reset(seed=3)
    b, _ = gaps.reset(seed=3)
    np.testing.assert_array_equal(a[:GAPS_AT], b[:GAPS_AT])
    np.testing.assert_array_equal(a[GAPS_AT:], b[GAPS_AT + 4:])
    u = gaps.unwrapped
    left, right = u.gap_middles(u.ego)
    lane = u.ego.loc.lane
    assert (left is None) == (lane == 0) and (right is None) == (lane == 2)
    for i, mid in enumerate((left, right)):
        expect = (0.0, 0.0) if mid is None else (1.0, mid / 50.0)
        np.testing.assert_allclose(b[GAPS_AT + 2 * i: GAPS_AT + 2 * i + 2], expect, atol=1e-6)


def test_on_the_ramps_s_curve_the_main_road_is_seen_before_it_is_beside():
    env = make_env("merge", alongside_features=True, gap_features=True, initial_lane=2)
    obs, info = env.reset(seed=0)
    assert info["lane_index"] == 2
    left_lane_block = obs[len(EGO_FEATURES) + len(LANE_FEATURES)]
    assert left_lane_block == 0.0  # not adjacent yet: the lane block has no left lane
    assert obs[GAPS_AT] == 1.0  # the gap block sees the lane the ramp merges into


def test_the_config_checks_and_the_checkpoint_records_them():
    from laneshift.actors.evaluation import checkpoint_env_settings
    from laneshift.config import ConfigError, EnvConfig

    with pytest.raises(ConfigError, match="env.gap_features"):
        EnvConfig(lane_features=False, gap_features=True)
    with pytest.raises(ValueError, match="gap_features extends the lane features"):
        make_env("straight", lane_features=False, gap_features=True)
    assert EnvConfig(gap_features=True).env_kwargs()["gap_features"] is True
    assert "gap_features" not in EnvConfig().env_kwargs()
    assert checkpoint_env_settings({"obs_shape": "92", "gap_features": "1"}) == \
        {"observation": "vector", "gap_features": True}
