"""Lane centre lines as chains of straight and circular segments, with fast evaluation.

highway-env describes a lane by one `StraightLane` or `CircularLane` per road section.  The
scenarios here are chains of such sections, so a lane is stored as a :class:`LanePath`: a start
pose and a list of (length, curvature) segments.  From it we build

* the highway-env lanes themselves (:meth:`LanePath.to_highway_lanes`: exact `StraightLane` /
  `CircularLane` objects, used for the `RoadNetwork` the scenario exposes), and
* fast numerics: vectorised ``position(s, lateral)`` for many vehicles at once (constant-speed
  traffic), and a scalar ``project(x, y)`` for the few free-driving vehicles, written with
  ``math`` because numpy's per-call overhead dominates at that size.

Conventions (those of highway-env): world y points *down* the rendered screen; heading is the
world angle of travel; the lane's lateral axis n = (-sin h, cos h) points to the *right* of the
direction of travel (towards higher lane indices); world curvature k = dh/ds, so k > 0 is a right
turn on screen.  A parallel lane offset by d along n has curvature k / (1 - k d) and length
L (1 - k d).

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np
from highway_env.road.lane import AbstractLane, CircularLane, StraightLane

TWO_PI = 2.0 * math.pi


def _wrap(a: float) -> float:
    return (a + math.pi) % TWO_PI - math.pi


class LanePath:
    """A lane centre line: start pose plus (length, world curvature) segments.

    ``closed`` paths (rings) wrap their arc length modulo :attr:`length`.
    """

    def __init__(
        self,
        start: Sequence[float],
        heading: float,
        segments: Sequence[tuple[float, float]],
        closed: bool = False,
        width: float = AbstractLane.DEFAULT_WIDTH,
    ) -> None:
        if not segments:
            raise ValueError("segments: a lane needs at least one segment")
        self.start = (float(start[0]), float(start[1]))
        self.heading = float(heading)
        self.segments = [(float(length), float(k)) for length, k in segments]
        self.closed = bool(closed)
        self.width = float(width)
        n = len(self.segments)
        self.seg_len = np.array([s[0] for s in self.segments])
        self.seg_k = np.array([s[1] for s in self.segments])
        self.seg_s0 = np.concatenate([[0.0], np.cumsum(self.seg_len)[:-1]])
        self.length = float(np.sum(self.seg_len))
        # Start pose of every segment.
        x0, y0, h0 = np.empty(n), np.empty(n), np.empty(n)
        x, y, h = self.start[0], self.start[1], self.heading
        for i, (length, k) in enumerate(self.segments):
            x0[i], y0[i], h0[i] = x, y, h
            x, y, h = _advance(x, y, h, length, k)
        self.seg_x0, self.seg_y0, self.seg_h0 = x0, y0, h0
        self.end_pose = (x, y, h)
        # Python lists for the scalar projection (indexing numpy scalars is slow).
        self._segs = [
            (float(x0[i]), float(y0[i]), float(h0[i]), self.segments[i][0], self.segments[i][1], float(self.seg_s0[i]))
            for i in range(n)
        ]
        self._s0_list = [float(v) for v in self.seg_s0]

    # -- construction helpers -----------------------------------------------------------------
    def offset(self, d: float) -> LanePath:
        """The parallel lane whose centre is ``d`` metres to the right (d < 0: left)."""
        sx = self.start[0] - d * math.sin(self.heading)
        sy = self.start[1] + d * math.cos(self.heading)
        segs = []
        for length, k in self.segments:
            f = 1.0 - k * d
            if f <= 0:
                raise ValueError(f"offset {d} m crosses the centre of a curve of radius {1 / k:.1f} m")
            segs.append((length * f, k / f))
        return LanePath((sx, sy), self.heading, segs, self.closed, self.width)

    def to_highway_lanes(self, line_types: Sequence[int]) -> list[AbstractLane]:
        """The highway-env lanes (one per segment) describing exactly this path."""
        lanes: list[AbstractLane] = []
        for (x0, y0, h0, length, k, _s0) in self._segs:
            if k == 0.0:
                end = (x0 + length * math.cos(h0), y0 + length * math.sin(h0))
                lanes.append(StraightLane((x0, y0), end, width=self.width, line_types=list(line_types)))
            else:
                radius = abs(1.0 / k)
                center = (x0 - math.sin(h0) / k, y0 + math.cos(h0) / k)
                if k > 0:  # clockwise on screen: highway-env heading = phase + pi/2
                    phase0 = h0 - math.pi / 2
                    phase1 = phase0 + length / radius
                else:
                    phase0 = h0 + math.pi / 2
                    phase1 = phase0 - length / radius
                lanes.append(
                    CircularLane(center, radius, phase0, phase1, clockwise=k > 0, width=self.width, line_types=list(line_types))
                )
        return lanes

    # -- vectorised evaluation ----------------------------------------------------------------
    def position(self, s: np.ndarray, lateral: float | np.ndarray = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, heading) at arc lengths ``s`` and lateral offsets (vectorised).

        Open paths extrapolate their first/last segment beyond [0, length]."""
        s = np.asarray(s, dtype=np.float64)
        if self.closed:
            s = np.mod(s, self.length)
        idx = np.clip(np.searchsorted(self.seg_s0, s, side="right") - 1, 0, len(self.segments) - 1)
        return _eval(self.seg_x0[idx], self.seg_y0[idx], self.seg_h0[idx], self.seg_k[idx], s - self.seg_s0[idx], lateral)

    def segment_at(self, s: float) -> int:
        """Index of the segment holding arc length ``s`` (clamped for open paths)."""
        if self.closed:
            s = s % self.length
        return int(min(max(bisect.bisect_right(self._s0_list, s) - 1, 0), len(self._segs) - 1))

    def heading_at(self, s: float) -> float:
        """Lane heading at arc length ``s`` (scalar)."""
        if self.closed:
            s = s % self.length
        x0, y0, h0, length, k, s0 = self._segs[self.segment_at(s)]
        return h0 + k * (s - s0)

    # -- scalar projection --------------------------------------------------------------------
    def project(self, x: float, y: float, hint: int = 0) -> tuple[float, float, float, float, int, bool]:
        """Project a point on the centre line, starting the search at segment ``hint``.

        Returns (s, lateral, lane heading, lane curvature, segment, inside) where ``inside`` is
        False when the foot of the point lies before the start or after the end of an open path.
        """
        segs = self._segs
        n = len(segs)
        i = min(max(hint, 0), n - 1)
        last_move = 0
        for _ in range(n + 1):
            x0, y0, h0, length, k, s0 = segs[i]
            dx, dy = x - x0, y - y0
            if k == 0.0:
                c, sn = math.cos(h0), math.sin(h0)
                u = dx * c + dy * sn
                lat = -dx * sn + dy * c
                h = h0
            else:
                r = 1.0 / k
                cx, cy = -math.sin(h0) * r, math.cos(h0) * r  # centre relative to the segment start
                px, py = dx - cx, dy - cy
                h = math.atan2(px * k, -py * k)  # heading at the foot point
                hm = h0 + 0.5 * k * length
                h = hm + _wrap(h - hm)
                u = (h - h0) / k
                lat = r - math.copysign(math.hypot(px, py), k)
            if u < 0.0 and (i > 0 or self.closed) and last_move != +1:
                i = (i - 1) % n
                last_move = -1
                continue
            if u > length and (i < n - 1 or self.closed) and last_move != -1:
                i = (i + 1) % n
                last_move = +1
                continue
            break
        inside = self.closed or (-1e-9 <= s0 + u <= self.length + 1e-9)
        return s0 + u, lat, h0 + k * u, k, i, inside


def _advance(x: float, y: float, h: float, length: float, k: float) -> tuple[float, float, float]:
    """End pose after driving ``length`` on curvature ``k`` from (x, y, h)."""
    half = 0.5 * k * length
    chord = length * (math.sin(half) / half if half != 0.0 else 1.0)
    return x + chord * math.cos(h + half), y + chord * math.sin(h + half), h + 2 * half


def _eval(x0, y0, h0, k, u, lateral) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # Chord formula, valid for k = 0 too: chord = u * sinc(k u / 2), direction h0 + k u / 2.
    half = 0.5 * k * u
    chord = u * np.sinc(half / np.pi)
    hm = h0 + half
    h = h0 + 2 * half
    x = x0 + chord * np.cos(hm) - lateral * np.sin(h)
    y = y0 + chord * np.sin(hm) + lateral * np.cos(h)
    return x, y, h


class LaneTable:
    """All lanes of a scenario in one table, to place many vehicles on many lanes in one call."""

    def __init__(self, paths: Sequence[LanePath]) -> None:
        self.paths = list(paths)
        base = 0.0
        s0, x0, y0, h0, k, first, last, bases = [], [], [], [], [], [], [], []
        for p in self.paths:
            first.append(len(s0))
            bases.append(base)
            s0.extend(base + p.seg_s0)
            x0.extend(p.seg_x0)
            y0.extend(p.seg_y0)
            h0.extend(p.seg_h0)
            k.extend(p.seg_k)
            last.append(len(s0) - 1)
            base += p.length + 1e6  # far apart: no lane's s range reaches the next lane's
        self.s0, self.x0, self.y0, self.h0, self.k = map(np.array, (s0, x0, y0, h0, k))
        self.first, self.last, self.base = np.array(first), np.array(last), np.array(bases)
        self.lengths = np.array([p.length for p in self.paths])
        self.closed = np.array([p.closed for p in self.paths])

    def position(self, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, heading) of vehicles on lane centres ``lane`` at arc lengths ``s``."""
        s = np.where(self.closed[lane], np.mod(s, self.lengths[lane]), s)
        g = self.base[lane] + s
        idx = np.clip(np.searchsorted(self.s0, g, side="right") - 1, self.first[lane], self.last[lane])
        return _eval(self.x0[idx], self.y0[idx], self.h0[idx], self.k[idx], g - self.s0[idx], 0.0)


__all__ = ["LanePath", "LaneTable"]
