"""Vehicles of the lane-change scenarios: free-driving agents and constant-speed traffic.

This replaces highway-env's slow parts while keeping its models:

* :class:`AgentVehicle` *is* a highway-env `Vehicle` (same kinematic bicycle equations, same
  size, usable by its graphics), but integrates with ``math`` and skips highway-env's per-step
  ``get_closest_lane_index`` over every lane of the network; lane bookkeeping is done by
  :func:`locate`, which only projects on the scenario's few logical lanes.
* :class:`Traffic` holds the constant-speed vehicles as numpy arrays: lane, arc length and speed.
  They follow their lane centre exactly, so two of them never collide (one speed per lane) and
  there is no need for highway-env's O(n^2) all-pairs collision loop - only the few agents are
  checked against everyone (:func:`collisions`).
* Open roads use a moving *traffic window* around the ego vehicle (``back`` metres behind, ``front``
  ahead): a vehicle that falls out of one end re-enters at the other end of the same lane, the
  window being a ring of length back + front.  Spacing is preserved modulo the ring, so traffic
  never overlaps and its density around the ego vehicle stays constant for any episode length.
  Closed roads (the ring) need no window: traffic circulates around the whole lane.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from highway_env.vehicle.kinematics import Vehicle

from .scenarios import Layout


class AgentVehicle(Vehicle):
    """A free-driving vehicle (the ego or a policy-driven one) on highway-env's bicycle model."""

    MAX_SPEED = 25.0
    MIN_SPEED = 0.0

    def __init__(self, layout: Layout, x: float, y: float, heading: float, speed: float, kind: str = "ego") -> None:
        # road=None skips highway-env's closest-lane search over the whole network.
        super().__init__(None, np.array([x, y]), heading, speed)
        self.layout = layout
        self.kind = kind
        self.hints = [0] * layout.lanes_count
        self.loc: Loc | None = None
        self.active = True
        self.offroad = False
        self.meta_lane: int | None = None  # meta-action target lane
        self.meta_speed_index = 0

    def on_state_update(self) -> None:  # lane bookkeeping is done by locate()
        pass

    def step(self, dt: float) -> None:
        """highway-env's kinematic bicycle (Vehicle.step), written with math for scalars."""
        steering = float(self.action["steering"])
        acceleration = float(self.action["acceleration"])
        beta = math.atan(0.5 * math.tan(steering))
        v, h = self.speed, self.heading
        self.position[0] += v * math.cos(h + beta) * dt
        self.position[1] += v * math.sin(h + beta) * dt
        self.heading = h + v * math.sin(beta) / (self.LENGTH / 2) * dt
        self.speed = min(max(v + acceleration * dt, self.MIN_SPEED), self.MAX_SPEED)


@dataclass(slots=True)
class Loc:
    """Where a vehicle is relative to every logical lane (world-lateral: + = right)."""

    s: list[float]
    lat: list[float]
    inside: list[bool]
    heading: list[float]  # lane heading at the foot point, per lane
    curvature: list[float]  # lane curvature at the foot point, per lane
    lane: int  # lane whose centre is nearest
    on_road: bool
    left_edge: float  # distance to the left edge of the paved area [m] (< 0 once beyond it)
    right_edge: float
    lane_end: float  # distance to the end of the current lane along it [m] (inf: no end)


def locate(layout: Layout, x: float, y: float, hints: list[int]) -> Loc:
    """Project a point on every lane of the layout (``hints`` are updated in place)."""
    n = layout.lanes_count
    s, lat, inside, hdg, curv = [0.0] * n, [0.0] * n, [False] * n, [0.0] * n, [0.0] * n
    best, best_d = 0, math.inf
    for i, path in enumerate(layout.paths):
        si, li, hi, ki, seg, ins = path.project(x, y, hints[i])
        hints[i] = seg
        s[i], lat[i], inside[i], hdg[i], curv[i] = si, li, ins, hi, ki
        if ins and abs(li) < best_d:
            best, best_d = i, abs(li)
    w2 = layout.paths[best].width / 2
    on_road = best_d <= w2
    # Paved area = the run of adjacent lanes around the nearest one (the merge ramp is only
    # adjacent to the main road along its parallel part).
    lo = best
    while lo > 0 and inside[lo - 1] and abs(lat[lo - 1] - lat[lo] - 2 * w2) < 0.5:
        lo -= 1
    hi = best
    while hi < n - 1 and inside[hi + 1] and abs(lat[hi] - lat[hi + 1] - 2 * w2) < 0.5:
        hi += 1
    path = layout.paths[best]
    lane_end = math.inf if path.closed else path.length - s[best]
    return Loc(s, lat, inside, hdg, curv, best, on_road, w2 + lat[lo], w2 - lat[hi], lane_end)


class Traffic:
    """Constant-speed, lane-following vehicles as arrays (see module docstring)."""

    def __init__(self, layout: Layout, lane_speeds: list[float], back: float, front: float) -> None:
        self.layout = layout
        self.lane_speeds = np.asarray(lane_speeds, dtype=np.float64)
        self.back, self.front = float(back), float(front)
        self.lane = np.zeros(0, dtype=np.int64)
        self.q = np.zeros(0)  # unbounded arc length (ring coordinate)
        self.speed = np.zeros(0)
        self.s = np.zeros(0)  # arc length on its lane, inside the window
        self.x = self.y = self.h = np.zeros(0)
        self._period = np.zeros(0)
        self._closed = np.zeros(0, dtype=bool)

    @property
    def count(self) -> int:
        return int(self.lane.size)

    def window_length(self, lane: int) -> float:
        path = self.layout.paths[lane]
        return path.length if path.closed else self.back + self.front

    def populate(
        self,
        rng: np.random.Generator,
        per_lane: dict[int, int],
        anchor: list[float],
        ego_lane: int,
        min_gap: float,
        ego_clearance: float,
    ) -> None:
        """Place ``per_lane[l]`` vehicles on each lane at random spacings >= ``min_gap`` (centre to
        centre), keeping ``ego_clearance`` in front of and behind the ego slot on ``ego_lane``."""
        lanes, qs = [], []
        for lane, n in per_lane.items():
            if n <= 0:
                continue
            period = self.window_length(lane)
            path = self.layout.paths[lane]
            origin = anchor[lane] - (0.0 if path.closed else self.back)
            if lane == ego_lane:
                mins = np.full(n + 1, min_gap)
                mins[0] = mins[-1] = ego_clearance
            else:
                mins = np.full(n, min_gap)
            extra = period - mins.sum()
            if extra < 0:
                raise ValueError(
                    f"vehicles_count: {n} vehicles do not fit on lane {lane} "
                    f"({period:.0f} m with {min_gap} m minimum spacing)"
                )
            gaps = mins + extra * rng.dirichlet(np.ones(mins.size))
            if lane == ego_lane:  # slot 0 is the ego vehicle, at the anchor
                pos = anchor[lane] + np.cumsum(gaps)[:-1]
            else:
                pos = origin + rng.uniform(0, period) + np.cumsum(gaps)
            lanes.append(np.full(n, lane))
            qs.append(pos)
        self.lane = np.concatenate(lanes) if lanes else np.zeros(0, dtype=np.int64)
        self.q = np.concatenate(qs) if qs else np.zeros(0)
        self.speed = self.lane_speeds[self.lane]
        self._period = np.array([self.window_length(int(lane)) for lane in self.lane])
        self._closed = self.layout.table.closed[self.lane]

    def remove(self, idx: np.ndarray) -> None:
        keep = np.ones(self.count, dtype=bool)
        keep[idx] = False
        self.lane, self.q, self.speed = self.lane[keep], self.q[keep], self.speed[keep]
        self._period, self._closed = self._period[keep], self._closed[keep]

    def advance(self, dt: float) -> None:
        self.q = self.q + self.speed * dt

    def place(self, anchor: np.ndarray) -> None:
        """Arc length and pose of every vehicle for the window around ``anchor`` (per-lane ego s)."""
        if self.count == 0:
            self.s = self.x = self.y = self.h = np.zeros(0)
            return
        a = anchor[self.lane] - self.back
        self.s = np.where(self._closed, self.q, a + np.mod(self.q - a, self._period))
        self.x, self.y, self.h = self.layout.table.position(self.lane, self.s)


def obb_overlap(
    x: float, y: float, h: float, length: float, width: float, X: np.ndarray, Y: np.ndarray, H: np.ndarray
) -> np.ndarray:
    """Separating-axis test of one rectangle against many of the same size (bool per rectangle)."""
    c, s = math.cos(h), math.sin(h)
    C, S = np.cos(H), np.sin(H)
    dx, dy = X - x, Y - y
    hl, hw = length / 2, width / 2
    sep = np.zeros(X.shape, dtype=bool)
    # Axes of the single rectangle: the others' radius on them depends on their heading.
    for ax, ay in ((c, s), (-s, c)):
        dist = np.abs(dx * ax + dy * ay)
        r_self = hl * abs(c * ax + s * ay) + hw * abs(-s * ax + c * ay)
        r_other = hl * np.abs(C * ax + S * ay) + hw * np.abs(-S * ax + C * ay)
        sep |= dist > r_self + r_other
    # Axes of the others (their own radius on them is hl, then hw).
    for (ax, ay), r_other in (((C, S), hl), ((-S, C), hw)):
        dist = np.abs(dx * ax + dy * ay)
        r_self = hl * np.abs(c * ax + s * ay) + hw * np.abs(-s * ax + c * ay)
        sep |= dist > r_self + r_other
    return ~sep


def collisions(
    x: float, y: float, h: float, length: float, width: float, X: np.ndarray, Y: np.ndarray, H: np.ndarray
) -> np.ndarray:
    """Indices of the rectangles (same size as the query) that overlap the query rectangle."""
    if X.size == 0:
        return np.zeros(0, dtype=np.int64)
    reach = math.hypot(length, width)  # sum of the two half-diagonals
    near = np.flatnonzero((X - x) ** 2 + (Y - y) ** 2 < reach * reach)
    if near.size == 0:
        return near
    hit = obb_overlap(x, y, h, length, width, X[near], Y[near], H[near])
    return near[hit]
