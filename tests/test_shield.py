"""The safety shield (``env.shield``, actors/envs/shield.py): the gap rule on hand-made views, and
in the env (an action it replaces is counted; a reckless driver that crashes without it survives
behind it, as ego vehicle and as policy vehicles; a checkpoint trained behind it is evaluated behind
it).

Room: tests, unit. May import: laneshift (any floor), pytest, the standard library.
"""

from __future__ import annotations

import math

import pytest

from laneshift.actors.envs import make_env
from laneshift.actors.envs.shield import FASTER, KEEP, LEFT, RIGHT, SLOWER, STRAIGHT, GapShield, ShieldView

INF = math.inf
FREE = (INF, 0.0, INF, 0.0)
SHIELD = GapShield(speed_step=0.1, curvature_step=0.01, dt=0.1, length=5.0)


def view(slots=(FREE, FREE, FREE), offset=0.0, heading=0.0, speed=12.0, lane_end=INF) -> ShieldView:
    return ShieldView(speed, offset, heading, 0.0, lane_end, 4.0, slots)


def act(speed_idx: int, curvature_idx: int) -> int:
    return 3 * speed_idx + curvature_idx


def test_with_free_lanes_and_room_every_action_stands():
    for a in range(9):
        assert SHIELD.safe_action(a, view()) == a


def test_a_car_alongside_on_the_left_stops_a_left_steer_at_the_lane_line_and_leaves_the_right_free():
    alongside = (-2.0, 0.0, -1.0, 0.0)  # overlapping lengthwise
    assert not SHIELD.lane_free(alongside)
    # Centred, a step of steering left keeps the body in its lane (it may still turn back): it stands.
    assert SHIELD.safe_action(act(KEEP, LEFT), view(slots=(FREE, alongside, FREE))) == act(KEEP, LEFT)
    # 0.8 m left of the centre, heading 0.05 rad left: one more step left and the body would cross
    # the line before it could turn back; straight on it still can.
    v = view(slots=(FREE, alongside, FREE), offset=0.8, heading=0.05)
    assert SHIELD.safe_action(act(KEEP, LEFT), v) == act(KEEP, STRAIGHT)
    assert SHIELD.safe_action(act(FASTER, RIGHT), v) == act(FASTER, RIGHT)
    # The same drift towards a free lane stands.
    assert SHIELD.safe_action(act(KEEP, LEFT), view(offset=0.8, heading=0.05)) == act(KEEP, LEFT)


def test_a_lane_change_into_a_slower_lane_needs_room_to_brake_to_its_speed():
    # The leader there is 5 m/s slower: braking at 0.9 m/s^2 takes 13.9 m beyond the 3 m kept.
    near, far = (15.0, -5.0, INF, 0.0), (18.0, -5.0, INF, 0.0)
    assert not SHIELD.lane_free(near) and SHIELD.lane_free(far)
    drifting_right = {"offset": -0.8, "heading": -0.05}
    assert SHIELD.safe_action(act(KEEP, RIGHT), view(slots=(FREE, FREE, near), **drifting_right)) == act(KEEP, STRAIGHT)
    assert SHIELD.safe_action(act(KEEP, RIGHT), view(slots=(FREE, FREE, far), **drifting_right)) == act(KEEP, RIGHT)


def test_a_faster_follower_needs_room_to_be_outrun():
    closing = (INF, 0.0, 10.0, 4.0)  # 10 m behind, 4 m/s faster: needs 3 + 8.9 m
    assert not SHIELD.lane_free(closing) and SHIELD.lane_free((INF, 0.0, 13.0, 4.0))


def test_already_heading_into_a_lane_that_is_not_free_it_steers_back():
    v = view(slots=(FREE, None, FREE), offset=0.9, heading=0.05)  # no lane on the left: the road's edge
    assert SHIELD.safe_action(act(KEEP, LEFT), v) % 3 == RIGHT
    assert SHIELD.safe_action(act(KEEP, STRAIGHT), v) % 3 == RIGHT


def test_it_brakes_for_a_close_slower_leader_and_speeds_up_for_a_close_faster_follower():
    assert SHIELD.safe_action(act(FASTER, STRAIGHT), view(slots=((5.0, -3.0, INF, 0.0), FREE, FREE))) == act(SLOWER, STRAIGHT)
    assert SHIELD.safe_action(act(SLOWER, STRAIGHT), view(slots=((INF, 0.0, 5.0, 3.0), FREE, FREE))) == act(FASTER, STRAIGHT)
    # A slower follower close behind is no threat.
    assert SHIELD.safe_action(act(SLOWER, STRAIGHT), view(slots=((INF, 0.0, 2.0, -1.0), FREE, FREE))) == act(SLOWER, STRAIGHT)
    # Both: the sooner contact decides (the leader, 1 s away, against the follower's 4 s).
    both = ((3.0, -3.0, 16.0, 4.0), FREE, FREE)
    assert SHIELD.safe_action(act(FASTER, STRAIGHT), view(slots=both)) == act(SLOWER, STRAIGHT)


def test_the_end_of_the_ramp_forces_braking_whoever_follows():
    v = view(slots=((INF, 0.0, 4.0, 3.0), FREE, FREE), speed=10.0, lane_end=60.0)  # needs 56 m + 8 m
    assert SHIELD.safe_action(act(FASTER, STRAIGHT), v) == act(SLOWER, STRAIGHT)
    assert SHIELD.safe_action(act(FASTER, STRAIGHT), view(speed=10.0, lane_end=200.0)) == act(FASTER, STRAIGHT)


def _reckless(env, seed: int) -> tuple[bool, int]:
    """Speed up while swerving left for 3 s, then slow down swerving right, for 300 steps."""
    obs, info = env.reset(seed=seed)
    shielded = 0
    for t in range(300):
        obs, _, terminated, truncated, info = env.step(act(FASTER, LEFT) if t % 60 < 30 else act(SLOWER, RIGHT))
        shielded += info.get("shielded", False)
        if terminated or truncated:
            break
    return info["crashed"], shielded


@pytest.mark.parametrize("road", ["straight", "merge", "curve", "roundabout"])
def test_a_reckless_driver_crashes_without_the_shield_and_mostly_survives_behind_it(road):
    seeds = range(6)
    bare = [_reckless(make_env(road, max_steps=300), s)[0] for s in seeds]
    assert all(bare)
    guarded = [_reckless(make_env(road, max_steps=300, shield=True), s) for s in seeds]
    assert sum(crashed for crashed, _ in guarded) <= 1, guarded  # a rule, not a proof: measured 0, 1, 0, 0 of 6
    assert all(n > 0 for _, n in guarded)


def test_the_shield_guards_the_paper_actions_only():
    with pytest.raises(ValueError, match="shield guards the paper action set"):
        make_env("straight", action_set="meta", shield=True)
    from laneshift.config import ConfigError, EnvConfig

    with pytest.raises(ConfigError, match="env.shield"):
        EnvConfig(scenario="lka", shield=True)


def test_a_checkpoint_says_it_was_trained_behind_the_shield():
    from laneshift.actors.evaluation import checkpoint_env_settings

    assert checkpoint_env_settings({"obs_shape": "88", "alongside_features": "1", "shield": "1"}) == \
        {"observation": "vector", "alongside_features": True, "shield": True}


def _reckless_copies(shield: bool, seed: int) -> int:
    """Crashes of 3 policy vehicles that all drive the reckless pattern, over one 300-step episode
    (the ego keeps its lane)."""
    env = make_env("straight", max_steps=300, policy_vehicles=3, shield=shield)
    clock = [0]

    def reckless(batch):
        clock[0] += 1
        return [act(FASTER, LEFT) if clock[0] % 60 < 30 else act(SLOWER, RIGHT)] * len(batch)

    env.unwrapped.set_npc_policy(reckless)
    env.reset(seed=seed)
    info = {}
    for _ in range(300):
        _, _, terminated, truncated, info = env.step(act(KEEP, STRAIGHT))
        if terminated or truncated:
            break
    return info["policy_vehicle_crashes"]


def test_policy_vehicles_driven_by_the_agent_drive_behind_its_shield_too():
    bare = sum(_reckless_copies(False, s) for s in range(3))
    guarded = sum(_reckless_copies(True, s) for s in range(3))
    assert bare >= 9, bare  # measured 20, 15 and 11 crashes an episode without the shield
    assert guarded <= bare // 5, (bare, guarded)  # measured 0, 0, 0 behind it


def test_the_shields_figures_are_the_drivers_by_default_and_set_from_the_config():
    from laneshift.actors.envs.demonstrator import ScriptedDriver
    from laneshift.config import SHIELD_DECEL, SHIELD_GAP, ConfigError, EnvConfig

    default = make_env("merge", shield=True).unwrapped.gap_shield
    driver = ScriptedDriver(make_env("merge"))
    assert (default.buffer, default.decel) == (SHIELD_GAP, SHIELD_DECEL) == (driver.buffer, driver.decel)
    cfg = EnvConfig(scenario="merge", shield=True, shield_gap=2.0, shield_decel=1.0)
    assert cfg.env_kwargs()["shield_gap"] == 2.0 and cfg.env_kwargs()["shield_decel"] == 1.0
    assert "shield_gap" not in EnvConfig(shield=True).env_kwargs()
    tuned = make_env("merge", **{k: v for k, v in cfg.env_kwargs().items() if k.startswith("shield")}).unwrapped.gap_shield
    assert (tuned.buffer, tuned.decel) == (2.0, 1.0)
    with pytest.raises(ConfigError, match="env.shield_gap.*needs env.shield=true"):
        EnvConfig(shield_gap=2.0)
    with pytest.raises(ConfigError, match="env.shield_decel"):
        EnvConfig(shield=True, shield_decel=1.5)  # more than the actions can brake
    with pytest.raises(ValueError, match="shield_decel"):
        make_env("merge", shield=True, shield_decel=1.5)


def test_a_smaller_gap_lets_a_lane_change_through_that_the_drivers_refuses():
    tight = GapShield(speed_step=0.1, curvature_step=0.01, dt=0.1, length=5.0, buffer=2.0, decel=1.0)
    follower = (INF, 0.0, 4.0, 1.5)  # 4 m behind on the left, 1.5 m/s faster
    assert not SHIELD.lane_free(follower)  # needs 3 + 1.5^2 / 1.8 = 4.25 m
    assert tight.lane_free(follower)  # needs 2 + 1.5^2 / 2 = 3.125 m
    drifting_left = view(slots=(FREE, follower, FREE), offset=0.8, heading=0.05)
    assert SHIELD.safe_action(act(KEEP, LEFT), drifting_left) == act(KEEP, STRAIGHT)
    assert tight.safe_action(act(KEEP, LEFT), drifting_left) == act(KEEP, LEFT)
