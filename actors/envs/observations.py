"""The vector observation (default): a flat float32 vector computed with numpy, no pandas.

Layout (``EGO_FEATURES``, then the lane block ``LANE_FEATURES`` for each of ``LANE_SLOTS`` when
``lane_features`` is on (the default), then ``ALONGSIDE_FEATURES`` for each slot when
``alongside_features`` is on, then ``GAP_FEATURES`` for the left and the right lane when
``gap_features`` is on, then ``vehicles_observed`` blocks of ``OTHER_FEATURES``), all
in the observer's frame with "left" positive, as in the paper's action convention:

ego block
    speed / 20 m/s; sin and cos of the heading relative to the nearest lane; lateral offset from
    that lane's centre / (lane width / 2) (+ = left); lane index / (lanes - 1); lanes to the
    target lane (lane index - target index) / (lanes - 1) (+ = target is on the left); on-target
    flag; distances to the left and right edges of the paved area / 10 m; lane curvature /
    curvature_step (+ = bends left); distance to the end of the lane / 100 m (capped at 1: only
    the merge ramp ends).
lanes (current, left neighbour, right neighbour; a missing neighbour is all zero)
    present; bumper-to-bumper gap to the nearest vehicle ahead on that lane / 50 m and its speed
    along the lane minus the observer's / 5 m/s; the same for the nearest vehicle behind. No
    vehicle within 100 m: gap 100 m, speed difference 0. The same facts are in the vehicle blocks
    below, but there the network must work out from positions which car shares which lane; handed
    over per lane they make the scripted driver much easier to imitate (the ablation with
    ``lane_features=False`` is in docs/results-history.md, round 2).
alongside (per lane slot, only with ``alongside_features``; after the lane block)
    a vehicle on that lane overlaps the observer lengthwise (1/0: bumper gap ahead or behind below
    0 m); the nearest bumper gap on that lane, ahead or behind, / 10 m, clipped to [-1, 1]. The lane
    block has the same gaps at 50 m, where a car alongside (a gap of -2 m) reads -0.04 beside a free
    lane's 2.0: a merge network trained without these steered into such cars from the on-ramp
    (docs/RESULTS.md, merge).
gaps (left, right; only with ``gap_features``; after the alongside block, or the lane block)
    the lane one to that side exists here (1/0; on the merge ramp the main road's right lane also
    along the ramp's S-curve, before it runs beside it); the signed distance along that lane from
    the observer to the middle of its nearest gap long enough to merge into (the scripted driver's
    rule, ``nearest_gap_middle``: 20 m between the centres of the cars around it), counting the cars
    within 100 m, / 50 m (+ = ahead). This is the quantity the scripted driver aligns its speed
    with before a lane change; from the vehicle blocks the network would have to find it by sorting
    positions per lane (docs/RESULTS.md, merge: the networks that miss there stay level with a car
    on the ramp's neighbouring lane until the ramp ends).
other vehicles (the K nearest within 60 m, nearest first; absent slots are all zero)
    presence; dx, dy / 50 m (dx forward, dy left); dvx, dvy / 10 m/s (relative velocity in the
    observer's frame); sin of the relative heading (+ = pointing left of the observer); lane
    difference (observer lane - other lane) / 2 (+ = other is on the left).

Every feature is clipped to [-5, 5], the bounds of the observation space.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math

import numpy as np

from .traffic import Loc

EGO_FEATURES = (
    "speed",
    "sin_heading",
    "cos_heading",
    "lateral",
    "lane",
    "lanes_to_target",
    "on_target",
    "left_edge",
    "right_edge",
    "lane_curvature",
    "lane_end",
)
OTHER_FEATURES = ("presence", "dx", "dy", "dvx", "dvy", "sin_dheading", "lane_delta")
LANE_SLOTS = ("current", "left", "right")
LANE_FEATURES = ("present", "front_gap", "front_dv", "rear_gap", "rear_dv")
ALONGSIDE_FEATURES = ("alongside", "near_gap")
GAP_SLOTS = ("left", "right")
GAP_FEATURES = ("lane", "gap_middle")
#: The centre-to-centre length of a gap worth aligning with: two car lengths (5 m), the scripted
#: driver's 3 m kept on both sides, 4 m to spare (its rule).
MERGE_GAP = 2 * (5.0 + 3.0) + 4.0
GAP_SCALE, GAP_RANGE, GAP_SPEED_SCALE = 50.0, 100.0, 5.0
NEAR_GAP_SCALE = 10.0
OBS_LIMIT = 5.0
SPEED_SCALE, DIST_SCALE, REL_SPEED_SCALE, EDGE_SCALE, END_SCALE = 20.0, 50.0, 10.0, 10.0, 100.0
PERCEPTION_RANGE = 60.0


def vector_size(vehicles_observed: int, lane_features: bool = True, alongside_features: bool = False,
                gap_features: bool = False) -> int:
    lanes = len(LANE_SLOTS) * len(LANE_FEATURES) if lane_features else 0
    alongside = len(LANE_SLOTS) * len(ALONGSIDE_FEATURES) if alongside_features else 0
    gaps = len(GAP_SLOTS) * len(GAP_FEATURES) if gap_features else 0
    return len(EGO_FEATURES) + lanes + alongside + gaps + vehicles_observed * len(OTHER_FEATURES)


def nearest_gap_middle(rel: np.ndarray, need: float) -> float:
    """The middle [m] of the gap nearest to 0 among the cars at sorted signed positions ``rel`` along
    a lane (their centres relative to the observer's), of those at least ``need`` long between the
    centres; beyond the last car on either side the lane is open (a gap that long starts there)."""
    edges = np.concatenate([[-np.inf], rel, [np.inf]])
    best = math.inf
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a < need:
            continue
        if math.isfinite(a) and math.isfinite(b):
            mid = (a + b) / 2
        elif math.isfinite(a):
            mid = a + need / 2
        elif math.isfinite(b):
            mid = b - need / 2
        else:
            mid = 0.0  # nobody on the lane
        if abs(mid) < abs(best):
            best = float(mid)
    return best


def gap_block(middles: list[float | None]) -> np.ndarray:
    """The gap features from the nearest gap's middle [m] per side (None: no lane there)."""
    out = np.zeros((len(GAP_SLOTS), len(GAP_FEATURES)), np.float32)
    for i, mid in enumerate(middles):
        if mid is not None:
            out[i] = (1.0, mid / GAP_SCALE)
    return out.ravel()


def lane_block(neighbours: list[tuple[float, float, float, float] | None], alongside: bool = False) -> np.ndarray:
    """The lane features from ``(front_gap, front_dv, rear_gap, rear_dv)`` per slot ([m], [m/s];
    ``None`` = no such lane; a gap of ``inf`` = nobody within range), then with ``alongside`` the
    alongside features of every slot (a missing lane: all zero)."""
    out = np.zeros((len(LANE_SLOTS), len(LANE_FEATURES)), np.float32)
    near = np.zeros((len(LANE_SLOTS), len(ALONGSIDE_FEATURES)), np.float32) if alongside else None
    for i, nb in enumerate(neighbours):
        if nb is None:
            continue
        front, dv_front, rear, dv_rear = nb
        out[i] = (1.0,
                  min(front, GAP_RANGE) / GAP_SCALE, dv_front / GAP_SPEED_SCALE if front <= GAP_RANGE else 0.0,
                  min(rear, GAP_RANGE) / GAP_SCALE, dv_rear / GAP_SPEED_SCALE if rear <= GAP_RANGE else 0.0)
        if near is not None:
            nearest = min(front, rear)
            near[i] = (float(nearest < 0.0), max(-1.0, min(1.0, nearest / NEAR_GAP_SCALE)))
    return out.ravel() if near is None else np.concatenate([out.ravel(), near.ravel()])


def vector_observation(
    x: float,
    y: float,
    heading: float,
    speed: float,
    loc: Loc,
    lane_width: float,
    lanes_count: int,
    target_lane: int,
    curvature_step: float,
    others_x: np.ndarray,
    others_y: np.ndarray,
    others_h: np.ndarray,
    others_v: np.ndarray,
    others_lane: np.ndarray,
    k: int,
    lanes: np.ndarray | None = None,
) -> np.ndarray:
    """Observation of one vehicle; ``others_*`` must not contain the observer itself; ``lanes`` is
    its :func:`lane_block` (None: the layout without lane features)."""
    out = np.zeros(len(EGO_FEATURES) + (0 if lanes is None else lanes.size) + k * len(OTHER_FEATURES), dtype=np.float32)
    span = max(1, lanes_count - 1)
    rel_heading = (heading - loc.heading[loc.lane] + math.pi) % (2 * math.pi) - math.pi
    # World heading/lateral/curvature grow to the right (y points down): negate for "left +".
    ego = (
        speed / SPEED_SCALE,
        -math.sin(rel_heading),
        math.cos(rel_heading),
        -loc.lat[loc.lane] / (lane_width / 2),
        loc.lane / span,
        (loc.lane - target_lane) / span,
        float(loc.lane == target_lane),
        loc.left_edge / EDGE_SCALE,
        loc.right_edge / EDGE_SCALE,
        -loc.curvature[loc.lane] / curvature_step,
        min(loc.lane_end, END_SCALE) / END_SCALE,
    )
    out[: len(ego)] = ego
    start = len(ego)
    if lanes is not None:
        out[start : start + lanes.size] = lanes
        start += lanes.size
    if k and others_x.size:
        dx, dy = others_x - x, others_y - y
        d2 = dx * dx + dy * dy
        idx = np.flatnonzero(d2 < PERCEPTION_RANGE**2)
        if idx.size:
            idx = idx[np.argsort(d2[idx], kind="stable")[:k]]
            c, s = math.cos(heading), math.sin(heading)
            dx, dy = dx[idx], dy[idx]
            vx = others_v[idx] * np.cos(others_h[idx]) - speed * c
            vy = others_v[idx] * np.sin(others_h[idx]) - speed * s
            block = np.empty((idx.size, len(OTHER_FEATURES)), dtype=np.float64)
            block[:, 0] = 1.0
            block[:, 1] = (dx * c + dy * s) / DIST_SCALE
            block[:, 2] = (dx * s - dy * c) / DIST_SCALE  # left of the observer: -n = (sin h, -cos h)
            block[:, 3] = (vx * c + vy * s) / REL_SPEED_SCALE
            block[:, 4] = (vx * s - vy * c) / REL_SPEED_SCALE
            block[:, 5] = -np.sin(others_h[idx] - heading)
            block[:, 6] = (loc.lane - others_lane[idx]) / 2.0
            out[start : start + block.size] = block.ravel()
    np.clip(out, -OBS_LIMIT, OBS_LIMIT, out=out)
    return out
