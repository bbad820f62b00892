"""How an action drives an agent vehicle of the lane-change env, the ego vehicle or a policy
vehicle (``Driving``, a base of ``lane_change.LaneChangeEnv``): a paper action (dv, kappa) becomes
steering and acceleration at once; a meta action (highway-env's) moves the vehicle's target lane or
target speed, which a lane-following controller then tracks every sub-step; and the keep-lane action
of a policy vehicle without a policy.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import numpy as np
from highway_env.vehicle.controller import ControlledVehicle

from .actions import META_ACTIONS, SPEED_CHANGES, curvature_to_steering
from .control import curvature_index, lane_errors, meta_acceleration, meta_steering
from .scenarios import Layout
from .traffic import AgentVehicle


class Driving:
    """Actions to vehicle controls (the env's action set, step sizes and frequencies; a meta lane
    change asks the env's ``lanes_adjacent``, lanes.LaneQueries)."""

    layout: Layout
    action_set: str
    actions: list[tuple[float, float]]
    policy_frequency: int
    curvature_step: float
    meta_target_speeds: np.ndarray

    def _command(self, v: AgentVehicle, action: int) -> None:
        if self.action_set == "paper":
            dv, kappa = self.actions[action]
            # Paper curvature is left-positive; highway-env's world heading grows to the right.
            v.action = {
                "steering": curvature_to_steering(-kappa, v.LENGTH),
                "acceleration": dv * self.policy_frequency,
            }
            return
        label = META_ACTIONS[action]
        if label in ("LANE_LEFT", "LANE_RIGHT"):
            # Like highway-env's is_reachable_from: only a lane adjacent to the current target lane.
            cand = v.meta_lane + (-1 if label == "LANE_LEFT" else 1)
            if self.lanes_adjacent(v.loc, v.meta_lane, cand):
                v.meta_lane = cand
        elif label == "FASTER":
            v.meta_speed_index = min(v.meta_speed_index + 1, self.meta_target_speeds.size - 1)
        elif label == "SLOWER":
            v.meta_speed_index = max(v.meta_speed_index - 1, 0)

    def _meta_control(self, v: AgentVehicle) -> None:
        lane = v.meta_lane
        path = self.layout.paths[lane]
        s_ahead = v.loc.s[lane] + v.speed * ControlledVehicle.TAU_PURSUIT
        v.action = {
            "steering": meta_steering(v.loc.lat[lane], path.heading_at(s_ahead), v.heading, v.speed, v.LENGTH),
            "acceleration": meta_acceleration(float(self.meta_target_speeds[v.meta_speed_index]), v.speed),
        }

    def _keep_lane_action(self, v: AgentVehicle) -> int:
        if not v.active:
            return 0
        if self.action_set == "meta":
            return 1  # IDLE
        offset, rel, curv = lane_errors(v.loc, v.loc.lane, v.heading)
        k = curvature_index(offset, rel, curv, v.speed / self.policy_frequency, self.curvature_step)
        return 3 * SPEED_CHANGES.index(0) + k

    def _meta_targets(self, v: AgentVehicle) -> None:
        """The meta controller's targets at a (re)start: the vehicle's lane, the grid speed nearest its own."""
        v.meta_lane = v.loc.lane
        v.meta_speed_index = int(np.argmin(np.abs(self.meta_target_speeds - v.speed)))
