"""Action sets of the lane-change envs.

**Paper actions** (default, ``action_set="paper"``, ``Discrete(9)``): every step the ego vehicle
changes its speed by ``dv`` and drives the step on a path of curvature ``kappa``:

    dv    in (0, +speed_step, -speed_step)          speed_idx 0, 1, 2   (paper: 0, +0.1, -0.1 m/s)
    kappa in (0, +curvature_step, -curvature_step)  curvature_idx 0, 1, 2 (paper: 0, +0.01, -0.01 rad/m)
    action index = 3 * speed_idx + curvature_idx

so index 0 is "keep speed, keep heading".  ``kappa > 0`` turns **left** as seen in the rendered
image and in the paper (towards lane index - 1, like highway-env's LANE_LEFT).  highway-env's
world y axis points down the screen, so a left turn *decreases* the world heading: the world
path curvature is ``-kappa``.  The curvature is realised through highway-env's kinematic bicycle
model (CoG midway between the axles, wheelbase = vehicle length L = 5 m), whose path curvature
for a steering angle delta is ``2 sin(beta) / L`` with ``beta = atan(tan(delta) / 2)``; inverting
it gives ``delta = atan(2 tan(asin(kappa L / 2)))`` (= atan(kappa L) to first order).

**Meta actions** (``action_set="meta"``, ``Discrete(5)``): highway-env's DiscreteMetaAction
labels and semantics (target lane +-1, target speed +- one step of a speed grid, tracked by
highway-env's ControlledVehicle lateral/speed controller laws).

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math

#: Paper defaults.
SPEED_STEP = 0.1  # [m/s] per step
CURVATURE_STEP = 0.01  # [rad/m]

SPEED_CHANGES = (0, +1, -1)  # multiples of speed_step, by speed_idx
CURVATURE_CHANGES = (0, +1, -1)  # multiples of curvature_step, by curvature_idx


def paper_actions(
    speed_step: float = SPEED_STEP, curvature_step: float = CURVATURE_STEP
) -> list[tuple[float, float]]:
    """The 9 (dv [m/s], kappa [rad/m]) pairs, indexed by 3 * speed_idx + curvature_idx."""
    return [(s * speed_step, c * curvature_step) for s in SPEED_CHANGES for c in CURVATURE_CHANGES]


#: The 9 paper actions with the paper's steps: index -> (dv [m/s], kappa [rad/m], +kappa = left).
PAPER_ACTIONS: list[tuple[float, float]] = paper_actions()


def paper_action_index(speed: int, turn: int) -> int:
    """Index of the paper action with speed change sign ``speed`` and turn sign ``turn``
    (each -1, 0 or +1; turn +1 = left)."""
    if speed not in (-1, 0, 1) or turn not in (-1, 0, 1):
        raise ValueError(f"speed and turn must be -1, 0 or 1, got {speed!r}, {turn!r}")
    return 3 * SPEED_CHANGES.index(speed) + CURVATURE_CHANGES.index(turn)


#: highway-env's DiscreteMetaAction.ACTIONS_ALL.
META_ACTIONS: dict[int, str] = {0: "LANE_LEFT", 1: "IDLE", 2: "LANE_RIGHT", 3: "FASTER", 4: "SLOWER"}


def curvature_to_steering(world_curvature: float, length: float) -> float:
    """Front steering angle [rad] that makes highway-env's kinematic bicycle drive a path of the
    given world curvature [rad/m] (exact inverse of its model; see module docstring)."""
    x = max(-1.0, min(1.0, world_curvature * length / 2.0))
    return math.atan(2.0 * math.tan(math.asin(x)))


def steering_to_curvature(steering: float, length: float) -> float:
    """Path curvature [rad/m] of highway-env's kinematic bicycle for a steering angle [rad]."""
    beta = math.atan(0.5 * math.tan(steering))
    return 2.0 * math.sin(beta) / length
