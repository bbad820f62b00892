"""What the lane-change env knows of its lanes around a vehicle (``LaneQueries``, a base of
``lane_change.LaneChangeEnv``): who is on a lane, the gaps and speeds ahead and behind, which lanes
are adjacent, the signed distance along a lane (wrapped on rings) and the lane features of the
vector observation. The scripted driver (demonstrator.py) reads the same queries.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math

import numpy as np

from .observations import GAP_RANGE, MERGE_GAP, gap_block, lane_block, nearest_gap_middle
from .scenarios import Layout
from .traffic import AgentVehicle, Loc, Traffic


class LaneQueries:
    """Lane queries over the env's traffic, ego vehicle and policy vehicles (the env's state)."""

    layout: Layout
    traffic: Traffic
    ego: AgentVehicle | None
    agents: list[AgentVehicle]
    alongside_features: bool
    gap_features: bool

    def lane_occupants(self, lane: int, exclude: AgentVehicle | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(arc length on ``lane``, speed) of every vehicle whose body overlaps ``lane``
        (constant-speed traffic on it, plus agents within a lane width of its centre)."""
        mask = self.traffic.lane == lane
        s, v = [self.traffic.s[mask]], [self.traffic.speed[mask]]
        for a in [self.ego, *self.agents]:
            if a is None or a is exclude or not a.active or a.loc is None:
                continue
            if a.loc.inside[lane] and abs(a.loc.lat[lane]) < self.layout.paths[lane].width - 0.5:
                s.append(np.array([a.loc.s[lane]]))
                v.append(np.array([a.speed * math.cos(a.heading - a.loc.heading[lane])]))
        return np.concatenate(s), np.concatenate(v)

    def lane_neighbours(self, v: AgentVehicle, lane: int) -> tuple[float, float, float, float]:
        """(gap ahead, speed ahead, gap behind, speed behind) around ``v`` on ``lane``: bumper-to-
        bumper distances [m] (``inf`` when nobody is there) and speeds along the lane [m/s]."""
        s_occ, v_occ = self.lane_occupants(lane, exclude=v)
        if s_occ.size == 0:
            return math.inf, 0.0, math.inf, 0.0
        d = self.lane_gap(lane, v.loc.s[lane], s_occ)
        ahead, behind = d >= 0, d < 0
        front = rear = math.inf
        v_front = v_rear = 0.0
        if ahead.any():
            i = int(np.argmin(np.where(ahead, d, np.inf)))
            front, v_front = float(d[i]) - v.LENGTH, float(v_occ[i])
        if behind.any():
            i = int(np.argmax(np.where(behind, d, -np.inf)))
            rear, v_rear = float(-d[i]) - v.LENGTH, float(v_occ[i])
        return front, v_front, rear, v_rear

    def lanes_adjacent(self, loc: Loc, lane: int, other: int) -> bool:
        """Is ``other`` a lane of the road right next to ``lane`` where ``loc`` is (one lane width
        apart laterally; the merge ramp is adjacent to the main road only along its parallel part)?"""
        if not 0 <= other < self.layout.lanes_count or not loc.inside[other]:
            return False
        return abs(abs(loc.lat[lane] - loc.lat[other]) - self.layout.paths[other].width) < 0.5

    def adjacent_lane(self, v: AgentVehicle, side: int) -> int | None:
        """The lane next to ``v``'s on ``side`` (-1 left, +1 right), if the road has one there."""
        lane = v.loc.lane + side
        return lane if self.lanes_adjacent(v.loc, v.loc.lane, lane) else None

    def lane_slots(self, v: AgentVehicle) -> list[tuple[float, float, float, float] | None]:
        """For ``v``'s current, left and right lane (None where the road has none): gap ahead, its
        speed minus ``v``'s forward speed, gap behind, its speed minus ``v``'s (bumper to bumper [m];
        ``inf`` when nobody is there). What the lane block of the observation (and the shield) read."""
        loc = v.loc
        forward = v.speed * math.cos(v.heading - loc.heading[loc.lane])
        slots: list[tuple[float, float, float, float] | None] = []
        for lane in (loc.lane, self.adjacent_lane(v, -1), self.adjacent_lane(v, +1)):
            if lane is None:
                slots.append(None)
                continue
            front, v_front, rear, v_rear = self.lane_neighbours(v, lane)
            slots.append((front, v_front - forward, rear, v_rear - forward))
        return slots

    def gap_middles(self, v: AgentVehicle) -> list[float | None]:
        """For the lanes one to ``v``'s left and right (None where the road has none here): the
        signed distance along that lane [m] to the middle of its nearest gap long enough to merge
        into, counting the vehicles within ``GAP_RANGE``. A lane counts from where ``v``'s position
        projects onto it (on the merge ramp: the main road's right lane along the S-curve too)."""
        loc = v.loc
        out: list[float | None] = []
        for lane in (loc.lane - 1, loc.lane + 1):
            if not (0 <= lane < self.layout.lanes_count and loc.inside[lane]):
                out.append(None)
                continue
            s_occ, _ = self.lane_occupants(lane, exclude=v)
            rel = np.asarray(self.lane_gap(lane, loc.s[lane], s_occ), dtype=float).reshape(-1)
            out.append(nearest_gap_middle(np.sort(rel[np.abs(rel) <= GAP_RANGE]), MERGE_GAP))
        return out

    def _lane_features(self, v: AgentVehicle) -> np.ndarray:
        block = lane_block(self.lane_slots(v), self.alongside_features)
        return np.concatenate([block, gap_block(self.gap_middles(v))]) if self.gap_features else block

    def lane_gap(self, lane: int, s_from: float, s_to: float | np.ndarray) -> float | np.ndarray:
        """Signed arc-length difference s_to - s_from on ``lane`` (wrapped on rings); ``s_to`` may
        be an array."""
        d = s_to - s_from
        path = self.layout.paths[lane]
        if path.closed:
            d = (d + path.length / 2) % path.length - path.length / 2
        return d
