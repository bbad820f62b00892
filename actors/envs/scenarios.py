"""Road layouts of the paper's four scenarios (figure 3), built from highway-env lanes.

Every layout is a list of *logical lanes* indexed 0..n-1 from left to right (highway-env's order:
lane 0 is the top one on screen when driving to the right, LANE_LEFT moves to index - 1).  Each
logical lane is a :class:`LanePath`; its highway-env `StraightLane` / `CircularLane` sections are
added to a `RoadNetwork` (nodes ``"<lane>:<section>"``) that the env exposes as ``env.road``.

Curvature limit: the paper's actions steer with |kappa| <= 0.01 rad/m, i.e. a 100 m minimum
turning radius.  A lane of radius R needs kappa = 1/R on average and a lane change on it needs
some margin on top, so every curve here has a radius of at least ~146 m.  That makes the
"roundabout" a large ring (lane radii 150-158 m) - the geometry adapts to the paper's action set,
not the other way round.

Default traffic (per scenario, overridable by env kwargs): lane speeds fall from left to right,
``linspace(14, 8, n)`` m/s, i.e. 14/11/8 m/s on three lanes.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from highway_env.road.lane import LineType
from highway_env.road.road import RoadNetwork

from .geometry import LanePath, LaneTable

LANE_WIDTH = 4.0


@dataclass
class Layout:
    """A scenario's road and where its traffic and ego vehicle go."""

    name: str
    paths: list[LanePath]
    #: lanes that carry constant-speed traffic (the merge ramp does not: it ends)
    npc_lanes: list[int]
    #: lanes where the ego vehicle (and policy vehicles) may start
    spawn_lanes: list[int]
    default_target: int
    #: ego start arc length on each lane (the ego starts level with this station)
    start_s: list[float]
    #: per lane, which side lines to draw: (left, right) in {"solid", "dashed", "none"}
    lines: list[tuple[str, str]]
    #: traffic window behind / ahead of the ego on open lanes [m]
    window_back: float = 120.0
    window_front: float = 180.0
    #: speed used for a lane without traffic (the ego's start speed there)
    ramp_speed_lane: int | None = None
    network: RoadNetwork = field(init=False)
    table: LaneTable = field(init=False)

    def __post_init__(self) -> None:
        self.network = RoadNetwork()
        for i, path in enumerate(self.paths):
            lt = [_LINE[self.lines[i][0]], _LINE[self.lines[i][1]]]
            for j, lane in enumerate(path.to_highway_lanes(lt)):
                self.network.add_lane(f"{i}:{j}", f"{i}:{j + 1}", lane)
        self.table = LaneTable(self.paths)

    @property
    def lanes_count(self) -> int:
        return len(self.paths)

    @property
    def closed(self) -> bool:
        return all(p.closed for p in self.paths)


_LINE = {"solid": LineType.CONTINUOUS_LINE, "dashed": LineType.STRIPED, "none": LineType.NONE}


def _parallel(reference: LanePath, n: int, ref_index: float) -> list[LanePath]:
    """n parallel lanes; lane ``ref_index`` (may be fractional) lies on the reference line."""
    return [reference.offset((i - ref_index) * LANE_WIDTH) for i in range(n)]


def _road_lines(n: int) -> list[tuple[str, str]]:
    return [("solid" if i == 0 else "dashed", "solid" if i == n - 1 else "none") for i in range(n)]


def _plain_road(name: str, paths: list) -> Layout:
    """A road of parallel lanes with traffic and spawns on every lane; lane 0 is the target."""
    n = len(paths)
    return Layout(name=name, paths=paths, npc_lanes=list(range(n)), spawn_lanes=list(range(n)),
                  default_target=0, start_s=[150.0] * n, lines=_road_lines(n))


def straight(lanes_count: int = 3, length: float = 3000.0) -> Layout:
    """Fig. 3(a): a straight multi-lane road."""
    ref = LanePath((0.0, 0.0), 0.0, [(length, 0.0)], width=LANE_WIDTH)
    return _plain_road("straight", _parallel(ref, lanes_count, 0))


def merge(lanes_count: int = 2, length: float = 3000.0) -> Layout:
    """Fig. 3(b): a straight main road and an on-ramp that merges into its right lane and ends.

    The ramp starts 6 m to the right of the main road's edge, joins it through an S-curve of two
    150 m-radius arcs, runs alongside for 150 m and then ends: driving past its end leaves the
    road.  ``lanes_count`` counts the main-road lanes; the ramp is lane ``lanes_count``; the target
    is the main road's right lane (the one the ramp merges into).
    """
    lead_in = 300.0  # main road before the ramp starts, so traffic behind the ego is on the road
    main_ref = LanePath((-lead_in, 0.0), 0.0, [(length, 0.0)], width=LANE_WIDTH)
    paths = _parallel(main_ref, lanes_count, 0)
    radius, shift = 150.0, 6.0
    theta = math.acos(1.0 - shift / (2.0 * radius))
    ramp_y = lanes_count * LANE_WIDTH + shift
    ramp = LanePath(
        (0.0, ramp_y),
        0.0,
        [(20.0, 0.0), (radius * theta, -1.0 / radius), (radius * theta, 1.0 / radius), (150.0, 0.0)],
        width=LANE_WIDTH,
    )
    paths.append(ramp)
    lines = _road_lines(lanes_count) + [("dashed", "solid")]
    lines[lanes_count - 1] = (lines[lanes_count - 1][0], "dashed")
    return Layout(
        name="merge",
        paths=paths,
        npc_lanes=list(range(lanes_count)),
        spawn_lanes=list(range(lanes_count + 1)),
        default_target=lanes_count - 1,
        start_s=[lead_in + 10.0] * lanes_count + [10.0],
        lines=lines,
        window_back=100.0,
        window_front=200.0,
        ramp_speed_lane=lanes_count - 1,
    )


def curve(lanes_count: int = 3, sections: int = 12) -> Layout:
    """Fig. 3(c): a winding multi-lane road of alternating 200 m-radius bends."""
    segs: list[tuple[float, float]] = [(200.0, 0.0)]
    k = 1.0 / 200.0
    turns = [(-k, 0.5), (k, 1.0), (-k, 1.0)]  # left 0.5 rad, then right 1 rad, left 1 rad, ...
    for i in range(sections):
        kk, ang = turns[0] if i == 0 else turns[1 + (i - 1) % 2]
        segs.append((ang / abs(kk), kk))
        segs.append((40.0, 0.0))
    ref = LanePath((0.0, 0.0), 0.0, segs, width=LANE_WIDTH)
    return _plain_road("curve", _parallel(ref, lanes_count, (lanes_count - 1) / 2))


def roundabout(lanes_count: int = 3, radius: float = 150.0) -> Layout:
    """Fig. 3(d): a multi-lane ring driven counter-clockwise on screen (centre on the left).

    Lane 0 is the inner lane (radius ``radius``); the target is the outer lane, the one a
    vehicle must be in to leave a roundabout.  Traffic circulates around the whole ring."""
    outer_free = radius
    ref = LanePath(
        (0.0, outer_free), 0.0, [(outer_free * math.pi / 2, -1.0 / outer_free)] * 4, closed=True, width=LANE_WIDTH
    )
    paths = _parallel(ref, lanes_count, 0)
    return Layout(
        name="roundabout",
        paths=paths,
        npc_lanes=list(range(lanes_count)),
        spawn_lanes=list(range(lanes_count)),
        default_target=lanes_count - 1,
        start_s=[0.0] * lanes_count,
        lines=_road_lines(lanes_count),
    )


BUILDERS = {"straight": straight, "merge": merge, "curve": curve, "roundabout": roundabout}

#: (min, max, default) lanes_count per scenario (merge counts main-road lanes).
LANES_RANGE = {"straight": (2, 6, 3), "merge": (1, 4, 2), "curve": (2, 5, 3), "roundabout": (2, 4, 3)}


def default_lane_speeds(n: int) -> list[float]:
    """Constant traffic speed of each lane, fastest on the left: linspace(14, 8, n) m/s."""
    return [11.0] if n == 1 else [float(v) for v in np.linspace(14.0, 8.0, n)]
