"""Reward presets of the paper's Table 1 as data, and the reward as a pure function.

Definitions used by every lane-change scenario (they are the env's, stated once here):

* **crashed**: the ego vehicle collided with another vehicle or left the road (entered the
  forbidden region).  The episode ends; the step's reward is the collision penalty *alone*
  (the motion and lane terms are 0 on that step, since the ego is no longer driving).
* **moving forward**: speed along the current lane's direction, ``speed * cos(heading error)``,
  is above ``FORWARD_SPEED_THRESHOLD`` (0.5 m/s).
* **stopped**: speed is below ``STOP_SPEED_THRESHOLD`` (0.5 m/s).  Speed is never negative
  (the paper's actions cannot reverse), so "stopped" and "moving forward" exclude each other;
  a vehicle faster than 0.5 m/s that points more than ~acos(0.5/speed) away from the lane
  direction is neither and gets 0 for the motion term.
* **in target lane** / **in non-target lane**: the lane whose centre is nearest to the ego
  vehicle's centre is (or is not) the target lane.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from dataclasses import dataclass

#: "moving forward" <=> speed along the lane > this [m/s].
FORWARD_SPEED_THRESHOLD = 0.5
#: "stopped" <=> speed < this [m/s].
STOP_SPEED_THRESHOLD = 0.5


@dataclass(frozen=True)
class RewardPreset:
    """One reward condition of Table 1, with its exploration schedule (linear-decay epsilon)."""

    condition: int
    collision: float  # collision or forbidden region (ends the episode)
    forward: float  # moving forward
    stopped: float  # stopped
    target_lane: float  # in the target lane
    non_target_lane: float  # in a non-target lane
    epsilon_initial: float
    epsilon_final: float


#: Table 1 of the paper; condition 5 is the one used for the evaluation (the env default).
REWARD_PRESETS: dict[int, RewardPreset] = {
    1: RewardPreset(1, -10.0, 0.5, -0.5, 1.5, -1.0, 1.0, 0.3),
    2: RewardPreset(2, -10.0, 0.5, -1.5, 1.0, -1.0, 1.0, 0.3),
    3: RewardPreset(3, -10.0, 0.5, -1.5, 1.0, -1.0, 1.0, 0.1),
    4: RewardPreset(4, -10.0, 0.0, -0.5, 1.5, -1.0, 1.0, 0.1),
    5: RewardPreset(5, -5.0, 1.0, -1.0, 1.0, -2.0, 1.0, 0.1),
}

DEFAULT_REWARD_PRESET = 5

REWARD_TERM_NAMES = ("collision", "forward", "stopped", "target_lane", "non_target_lane")


def motion_flags(speed: float, forward_speed: float) -> tuple[bool, bool]:
    """(moving_forward, stopped) from the speed and the speed along the lane direction [m/s]."""
    return forward_speed > FORWARD_SPEED_THRESHOLD, speed < STOP_SPEED_THRESHOLD


def compute_reward(
    preset: RewardPreset | int,
    *,
    crashed: bool,
    moving_forward: bool,
    stopped: bool,
    on_target_lane: bool,
) -> tuple[float, dict[str, float]]:
    """Reward of one step and its per-term breakdown (the terms sum to the reward).

    Pure function of the situation; ``preset`` is a :class:`RewardPreset` or a condition number 1-5.
    """
    p = get_preset(preset)
    terms = dict.fromkeys(REWARD_TERM_NAMES, 0.0)
    if crashed:
        terms["collision"] = p.collision
    else:
        if moving_forward:
            terms["forward"] = p.forward
        if stopped:
            terms["stopped"] = p.stopped
        if on_target_lane:
            terms["target_lane"] = p.target_lane
        else:
            terms["non_target_lane"] = p.non_target_lane
    return float(sum(terms.values())), terms


def get_preset(preset: RewardPreset | int) -> RewardPreset:
    """Resolve a condition number (1-5) or pass a preset through; ValueError otherwise."""
    if isinstance(preset, RewardPreset):
        return preset
    if isinstance(preset, bool) or preset not in REWARD_PRESETS:
        raise ValueError(f"reward_preset must be one of {sorted(REWARD_PRESETS)}, got {preset!r}")
    return REWARD_PRESETS[preset]
