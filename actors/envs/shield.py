"""A safety shield for the paper's 9 actions (``shield=True``, off by default): before a step, an
action that a gap rule calls unsafe is replaced by a safe one, the way a vehicle's safety layer
overrides its planner (shielding, Alshiekh et al. 2018; for lane changes, Mirchevska et al. 2018,
Krasowski et al. 2020).

What it reads is what the vector observation's lane block and alongside block hold (the gap and
speed difference to the nearest vehicle ahead and behind on the current, left and right lane, a car
alongside), the ego's speed, lateral offset, heading and lane curvature, and the distance to the end
of its lane: nothing the network could not see. The rule, with the driver's own planning
deceleration (``decel``) and bumper gap (``buffer``):

* **lanes**: a neighbouring lane is free when it exists, nobody overlaps the ego lengthwise, the
  leader there is far enough ahead to brake to its speed, and the follower far enough behind to
  speed up to its own (traffic never brakes). An action whose curvature would carry the ego's body
  into a lane that is not free (past ``edge`` metres from its lane's centre, even if it then steers
  back as hard as the action set allows), or past the far side of a free one, becomes a curvature
  that does not (straight ahead first).
* **speed**: slower is forced when the leader on the ego's own lane, or on a lane its body reaches
  into, or the end of the ego's lane (the merge ramp) is too close to brake for after one more step;
  faster when such a follower is closing too fast to outrun. With both, the sooner contact decides.

The replaced action is what the env executes; the agent's own action is what it returns to the
learner (so the learner learns the shielded MDP: an unsafe action is worth what its replacement is).

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from .actions import CURVATURE_CHANGES, SPEED_CHANGES

#: One lane slot's neighbours: (gap ahead, its speed minus the ego's, gap behind, its speed minus
#: the ego's); bumper to bumper [m], ``inf`` when nobody is there. None: no such lane.
Slot = tuple[float, float, float, float] | None

KEEP, FASTER, SLOWER = (SPEED_CHANGES.index(d) for d in (0, +1, -1))
STRAIGHT, LEFT, RIGHT = (CURVATURE_CHANGES.index(d) for d in (0, +1, -1))


class ShieldView(NamedTuple):
    """What the shield reads before a step (left positive, as the observation)."""

    speed: float  # [m/s]
    offset: float  # lateral offset from the current lane's centre [m]
    rel_heading: float  # heading relative to the current lane [rad]
    lane_curvature: float  # [rad/m]
    lane_end: float  # distance to the end of the current lane [m] (inf: it does not end)
    lane_width: float  # the current lane's [m]
    slots: tuple[Slot, Slot, Slot]  # current, left, right


@dataclass(frozen=True)
class GapShield:
    """The gap rule. ``speed_step`` [m/s] and ``curvature_step`` [rad/m] are the action set's,
    ``dt`` the time of one decision [s], ``length`` the ego's [m]."""

    speed_step: float
    curvature_step: float
    dt: float
    length: float
    buffer: float = 3.0  # bumper-to-bumper gap kept [m] (the scripted driver's)
    decel: float = 0.9  # the speed change it plans with [m/s^2] (the driver's; the actions allow 1)
    edge: float = 1.0  # lateral offset [m] beyond which a 2 m wide body reaches into the next lane

    def lane_free(self, slot: Slot) -> bool:
        if slot is None:
            return False
        front, dv_front, rear, dv_rear = slot
        if min(front, rear) < 0.0:  # someone alongside
            return False
        closing_ahead, closing_behind = max(-dv_front, 0.0), max(dv_rear, 0.0)
        return (front > self.buffer + closing_ahead**2 / (2 * self.decel)
                and rear > self.buffer + closing_behind**2 / (2 * self.decel))

    def _reach(self, view: ShieldView, curvature_idx: int) -> tuple[float, float]:
        """(leftmost, rightmost) lateral offset the body's centre reaches if the ego takes this
        curvature for one step and then steers back as hard as it can."""
        v = max(view.speed, 0.5)
        kappa = CURVATURE_CHANGES[curvature_idx] * self.curvature_step
        heading = view.rel_heading + (kappa - view.lane_curvature) * v * self.dt
        offset = view.offset + v * self.dt * math.sin(heading)
        back = max(self.curvature_step - abs(view.lane_curvature), 0.2 * self.curvature_step)
        swing = heading * heading / (2 * back)
        return offset + (swing if heading > 0 else 0.0), offset - (swing if heading < 0 else 0.0)

    def _bounds(self, view: ShieldView) -> tuple[float, float]:
        """How far [m] left and right of its lane's centre the body may go: ``edge`` on a side whose
        lane is not free, the far side of a free neighbouring lane (one lane change at a time)."""
        left = self.edge + (view.lane_width if self.lane_free(view.slots[1]) else 0.0)
        right = self.edge + (view.lane_width if self.lane_free(view.slots[2]) else 0.0)
        return left, right

    def forced_speed(self, view: ShieldView, reach: tuple[float, float]) -> int | None:
        """SLOWER, FASTER or None (the action's own speed part is safe). It looks at the ego's lane
        and at a neighbouring lane its body reaches into (``reach``: the chosen curvature's
        (leftmost, rightmost) offsets; a lane change)."""
        lanes = [view.slots[0]]
        leftmost, rightmost = reach
        if leftmost > self.edge:
            lanes.append(view.slots[1])
        if rightmost < -self.edge:
            lanes.append(view.slots[2])
        # The most urgent threat on either side: its time to contact [s] at the closing speed it
        # will have after one more step of the wrong speed change (inf: none).
        ahead = behind = math.inf
        for slot in lanes:
            if slot is None:
                continue
            front, dv_front, rear, dv_rear = slot
            closing_ahead, closing_behind = -dv_front + self.speed_step, dv_rear + self.speed_step
            if 0.0 <= front < self.buffer + max(closing_ahead, 0.0) ** 2 / (2 * self.decel):
                ahead = min(ahead, front / max(closing_ahead, 1e-3))
            if closing_behind > 0.0 and 0.0 <= rear < self.buffer + closing_behind**2 / (2 * self.decel):
                behind = min(behind, rear / closing_behind)
        room = view.lane_end - self.length - self.buffer  # stop before the end of the lane (merge ramp)
        if room < (view.speed + self.speed_step) ** 2 / (2 * self.decel):
            return SLOWER  # the road ends: no follower makes driving on safer
        if ahead == behind == math.inf:
            return None
        return SLOWER if ahead <= behind else FASTER

    def safe_action(self, action: int, view: ShieldView) -> int:
        """``action`` (index = 3 * speed + curvature) if the rule calls it safe, else its replacement."""
        speed_idx, curvature_idx = divmod(int(action), 3)
        left, right = self._bounds(view)
        reach = [self._reach(view, c) for c in range(3)]
        # How far [m] each curvature carries the body past where it may go.
        risk = [max(0.0, leftmost - left) + max(0.0, -right - rightmost) for leftmost, rightmost in reach]
        if risk[curvature_idx] > 0.0:
            safe = [c for c in (STRAIGHT, LEFT, RIGHT) if risk[c] == 0.0]
            curvature_idx = safe[0] if safe else min(range(3), key=risk.__getitem__)
        forced = self.forced_speed(view, reach[curvature_idx])
        return 3 * (speed_idx if forced is None else forced) + curvature_idx
