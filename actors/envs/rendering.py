"""Top-down rendering of a scenario: the paper's grayscale observation and RGB frames.

Drawn with pygame on an off-screen `Surface` - `pygame.display` is never initialised, so the
frames are real whatever ``SDL_VIDEODRIVER`` says.  (highway-env's own `EnvViewer` disables
drawing altogether when ``SDL_VIDEODRIVER=dummy`` and silently returns black frames; this
renderer does not go through it.)  Lane surfaces are polygons sampled from the lane centre lines
(which are exactly highway-env's `StraightLane` / `CircularLane` sections, see geometry.py),
vehicles are their rotated rectangles.  Only what falls inside the view is drawn.

Image orientation: world x to the right (columns), world y downwards (rows), the view around the
ego vehicle (centred, or at ``centering`` across the width) and not rotated with it; on the straight
road the traffic drives to the right.

The palette makes the paper's figure-3 regions distinguishable in grayscale:
off-road (forbidden region) black, non-target lanes dark grey, the target lane light grey, lane
markings near-white, constant-speed vehicles very dark, policy-driven vehicles mid grey, the ego
vehicle white.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402
import pygame  # noqa: E402

from .scenarios import Layout  # noqa: E402

# pygame-ce loads pygame.surfarray lazily (importlib.util.LazyLoader), which is not thread-safe
# before Python 3.12: two env threads drawing their first frame at once (in-process mode's
# workers) could see the module half-loaded ("no attribute 'pixels_red'"), and that worker died.
# Reading the functions here loads it once, under this module's import lock.
_pixels_red, _array3d = pygame.surfarray.pixels_red, pygame.surfarray.array3d

#: Grey level of each element in the grayscale observation.
GRAY_PALETTE: dict[str, int] = {
    "offroad": 0,
    "lane": 100,
    "target": 170,
    "line": 215,
    "npc": 45,
    "policy": 135,
    "ego": 255,
}

#: Colours of the paper's figure 3 for RGB frames.
RGB_PALETTE: dict[str, tuple[int, int, int]] = {
    "offroad": (0, 0, 0),
    "lane": (70, 160, 70),  # non-target lanes: green
    "target": (60, 110, 230),  # target lane: blue
    "line": (235, 235, 235),
    "npc": (170, 220, 50),  # constant-speed vehicles: yellow-green
    "policy": (120, 205, 255),  # policy copies: light blue
    "ego": (255, 105, 180),  # ego agent: pink
}

STRIPE_SPACING, STRIPE_LENGTH = 4.33, 3.0  # highway-env's LaneGraphics values [m]


class TopDownRenderer:
    """Renders a window of ``size`` = (height, width) pixels at ``scaling`` pixels per metre.

    ``supersample`` k > 1 draws at k times the resolution (k x k pixels per output pixel) and
    averages each k x k block: an anti-aliased frame, in which an edge's grey level says where
    inside its pixel the edge lies. Without it pygame's polygons cover whole pixels, so a car
    moves in the frame only when it crosses a pixel boundary: at 2 px/m a 1 m/s speed gap is 0.2 px
    per frame, invisible across a 4-frame stack (docs/RESULTS.md, how the pixel network crashes).

    ``centering`` is where the centre given to :meth:`render` (the ego) lies across the window's
    width, as a fraction from its left (low x) edge: 0.5 centres it; highway-env's observations use
    0.3, which shows 70 % of the window ahead of a car driving towards +x.
    """

    def __init__(self, layout: Layout, size: tuple[int, int], scaling: float, grayscale: bool,
                 supersample: int = 1, centering: float = 0.5) -> None:
        if int(supersample) != supersample or supersample < 1:
            raise ValueError(f"supersample must be an integer >= 1, got {supersample!r}")
        if not 0.0 < centering < 1.0:
            raise ValueError(f"centering must be in (0, 1), got {centering!r}")
        self.layout = layout
        self.supersample = k = int(supersample)
        self.out_height, self.out_width = int(size[0]), int(size[1])
        # What is drawn: k times the pixels at k times the scaling (the same window in metres).
        self.height, self.width = self.out_height * k, self.out_width * k
        self.scaling = float(scaling) * k
        self.grayscale = grayscale
        # Metres from the given centre to the window's centre along x (0 when centred).
        self.shift_x = (0.5 - float(centering)) * self.width / self.scaling
        palette = GRAY_PALETTE if grayscale else RGB_PALETTE
        self.colors = {k: ((v, v, v) if isinstance(v, int) else v) for k, v in palette.items()}
        self.surface = pygame.Surface((self.width, self.height))
        # Half-diagonal of the view in metres, plus a lane width: what can be visible.
        self.reach = math.hypot(self.width, self.height) / 2 / self.scaling + 4.0
        self._hints = [0] * layout.lanes_count

    def render(
        self,
        center: tuple[float, float],
        target_lane: int,
        vehicles: list[tuple[np.ndarray, np.ndarray, np.ndarray, str]],
        length: float,
        width: float,
    ) -> np.ndarray:
        """Draw the view around ``center`` (at ``centering`` across the width); ``vehicles`` are
        (x, y, heading, palette key) arrays.

        Returns (H, W) uint8 for grayscale, (H, W, 3) uint8 otherwise."""
        surf = self.surface
        surf.fill(self.colors["offroad"])
        center = (center[0] + self.shift_x, center[1])  # the window's centre from here on
        ox = center[0] - self.width / 2 / self.scaling
        oy = center[1] - self.height / 2 / self.scaling
        lanes = []
        for i, path in enumerate(self.layout.paths):
            s_c, lat_c, _, _, seg, _ = path.project(center[0], center[1], self._hints[i])
            self._hints[i] = seg
            if abs(lat_c) > self.reach + path.width:
                continue
            lo, hi = s_c - self.reach, s_c + self.reach
            if not path.closed:
                lo, hi = max(lo, 0.0), min(hi, path.length)
                if hi <= lo:
                    continue
            lanes.append((i, path, lo, hi))
        # Lane surfaces first (non-target then target, so the target stays visible at overlaps).
        for i, path, lo, hi in sorted(lanes, key=lambda t: t[0] == target_lane):
            s = np.linspace(lo, hi, max(2, int((hi - lo) / 2.0) + 1))
            xl, yl, _ = path.position(s, -path.width / 2)
            xr, yr, _ = path.position(s[::-1], path.width / 2)
            pts = self._pix(np.concatenate([xl, xr]), np.concatenate([yl, yr]), ox, oy)
            pygame.draw.polygon(surf, self.colors["target" if i == target_lane else "lane"], pts)
        line_w = max(1, int(round(0.3 * self.scaling)))
        for i, path, lo, hi in lanes:
            for side, style in zip((-1, 1), self.layout.lines[i]):
                if style == "solid":
                    s = np.linspace(lo, hi, max(2, int((hi - lo) / 2.0) + 1))
                    x, y, _ = path.position(s, side * path.width / 2)
                    pygame.draw.lines(surf, self.colors["line"], False, self._pix(x, y, ox, oy), line_w)
                elif style == "dashed":
                    starts = np.arange(math.floor(lo / STRIPE_SPACING) * STRIPE_SPACING, hi, STRIPE_SPACING)
                    ends = np.minimum(starts + STRIPE_LENGTH, hi)
                    starts = np.maximum(starts, lo)
                    ok = ends > starts
                    if not ok.any():
                        continue
                    xa, ya, _ = path.position(starts[ok], side * path.width / 2)
                    xb, yb, _ = path.position(ends[ok], side * path.width / 2)
                    pa, pb = self._pix(xa, ya, ox, oy), self._pix(xb, yb, ox, oy)
                    for a, b in zip(pa, pb):
                        pygame.draw.line(surf, self.colors["line"], a, b, line_w)
        # Vehicles: rotated rectangles of the ones inside the view.
        half_w = self.width / 2 / self.scaling + length
        half_h = self.height / 2 / self.scaling + length
        cx, cy = center
        corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], dtype=np.float64) * (length / 2, width / 2)
        for X, Y, H, key in vehicles:
            vis = np.flatnonzero((np.abs(X - cx) < half_w) & (np.abs(Y - cy) < half_h))
            color = self.colors[key]
            for j in vis:
                c, s = math.cos(H[j]), math.sin(H[j])
                px = X[j] + corners[:, 0] * c - corners[:, 1] * s
                py = Y[j] + corners[:, 0] * s + corners[:, 1] * c
                pygame.draw.polygon(surf, color, self._pix(px, py, ox, oy))
        if self.grayscale:
            return self._downsample(np.array(_pixels_red(surf)).T)
        return self._downsample(np.transpose(_array3d(surf), (1, 0, 2)))

    def _downsample(self, drawn: np.ndarray) -> np.ndarray:
        """The drawn (H k, W k[, 3]) uint8 image as (H, W[, 3]): each k x k block's mean, rounded."""
        k = self.supersample
        if k == 1:
            return drawn.copy()
        # The block sums as k strided adds per axis: numpy's sum over the axes of a (H, k, W, k)
        # view of the transposed surface took about 4 ms a frame at k = 4 (cProfile), these 0.2 ms.
        wide = drawn.astype(np.uint16)  # k * k * 255 <= 16,320 for k <= 8
        rows = sum(wide[i::k] for i in range(k))
        sums = sum(rows[:, j::k] for j in range(k))
        return ((sums + (k * k) // 2) // (k * k)).astype(np.uint8)

    def _pix(self, x: np.ndarray, y: np.ndarray, ox: float, oy: float) -> list[tuple[float, float]]:
        k = self.scaling
        return list(zip(((x - ox) * k).tolist(), ((y - oy) * k).tolist()))
