"""Low-level control laws shared by the env (meta actions, policy-vehicle fallback) and the
scripted demonstrator.

Sign convention here: the paper's, "left" positive (lateral offset, relative heading, curvature).

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math

from highway_env.vehicle.controller import ControlledVehicle

from .actions import CURVATURE_CHANGES, SPEED_CHANGES
from .traffic import Loc


def lane_errors(loc: Loc, lane: int, heading: float) -> tuple[float, float, float]:
    """(lateral offset from ``lane``'s centre, heading relative to it, its curvature), left +."""
    rel = (heading - loc.heading[lane] + math.pi) % (2 * math.pi) - math.pi
    return -loc.lat[lane], -rel, -loc.curvature[lane]


def curvature_index(
    offset: float,
    rel_heading: float,
    lane_curvature: float,
    step_length: float,
    curvature_step: float,
    max_heading: float = 0.12,
) -> int:
    """Curvature index (0 keep, 1 left, 2 right) that steers onto the centre line.

    A heading reference that the available curvature margin can still take back to zero by the
    time the offset is gone (psi_ref = -sign(e) sqrt(2 a |e|), capped at ``max_heading``), then the
    quantised curvature closest to reaching it within one step of ``step_length`` metres.
    """
    margin = max(curvature_step - abs(lane_curvature), 0.2 * curvature_step)
    a = 0.6 * margin
    psi_ref = -math.copysign(min(max_heading, math.sqrt(2.0 * a * abs(offset))), offset)
    wanted = lane_curvature + (psi_ref - rel_heading) / max(step_length, 0.05)
    best, best_err = 0, math.inf
    for idx, sign in enumerate(CURVATURE_CHANGES):
        err = abs(sign * curvature_step - wanted)
        if err < best_err - 1e-12:
            best, best_err = idx, err
    return best


def speed_index(current: float, desired: float, deadband: float = 0.05) -> int:
    """Speed index (0 keep, 1 faster, 2 slower) towards ``desired`` [m/s]."""
    if desired > current + deadband:
        return SPEED_CHANGES.index(+1)
    if desired < current - deadband:
        return SPEED_CHANGES.index(-1)
    return SPEED_CHANGES.index(0)


def meta_steering(offset: float, lane_heading_ahead: float, heading: float, speed: float, length: float) -> float:
    """highway-env's ControlledVehicle.steering_control law (world signs: ``offset`` = lateral
    position on the target lane, + right; returns the world steering angle)."""
    cv = ControlledVehicle
    lateral_speed_command = -cv.KP_LATERAL * offset
    heading_command = math.asin(max(-1.0, min(1.0, lateral_speed_command / max(speed, 1e-2))))
    heading_ref = lane_heading_ahead + max(-math.pi / 4, min(math.pi / 4, heading_command))
    err = (heading_ref - heading + math.pi) % (2 * math.pi) - math.pi
    heading_rate_command = cv.KP_HEADING * err
    slip = math.asin(max(-1.0, min(1.0, length / 2 / max(speed, 1e-2) * heading_rate_command)))
    steering = math.atan(2 * math.tan(slip))
    return max(-cv.MAX_STEERING_ANGLE, min(cv.MAX_STEERING_ANGLE, steering))


def meta_acceleration(target_speed: float, speed: float) -> float:
    """highway-env's ControlledVehicle.speed_control law."""
    return ControlledVehicle.KP_A * (target_speed - speed)
