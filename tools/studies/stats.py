"""Statistics across runs (seeds) for the studies' tables and learning curves.

A study's uncertainty is between runs: two seeds of one method can end far apart (none: 40 % and
5 % survival in round 1), while the episodes of one run share its network. So an interval comes
from resampling runs, not episodes: a percentile bootstrap over runs for a mean, as rliable does
(one task, so no stratification), with 95 % intervals from 10,000 seeded resamples. Pooling the
episodes of all seeds and taking a Wilson interval treats them as independent draws and
understates the uncertainty when there are two seeds.

- :func:`bootstrap_ci`: the interval of the mean over runs (axis 0), for one number per run or a
  curve per run (every point resampled with the same runs, so a band is one set of resamples).
- :func:`curves_on_grid`: per-run curves (already smoothed) put on a common x grid (env steps,
  wall-clock seconds) over the range every run covers, with their mean and bootstrap band.
- :func:`paired_difference_ci`: the interval of a difference between two groups of runs that drove the same
  episodes (recipe against recipe, networks against the driver), resampling the episodes as well as the runs: with
  a few hundred fixed episodes their draw is as large a part of the uncertainty as the seeds.
- :func:`drop_noise_floor`: how far a policy that never changes falls below its running best on
  evaluations of a few episodes, so that a measured drop can be told from evaluation noise.

Room: the tools (studies). May import: numpy only (no laneshift component; the experiment commands import this).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

#: Resamples of the bootstrap (rliable's default order of magnitude).
RESAMPLES = 10_000
#: Seed of the bootstrap's generator: the same data give the same interval.
SEED = 0


def bootstrap_ci(values: Sequence[float] | np.ndarray, confidence: float = 0.95, resamples: int = RESAMPLES,
                 seed: int = SEED) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Percentile bootstrap interval of the mean over runs.

    ``values``: one number per run (shape ``(runs,)``) or one row per run (``(runs, points)``).
    Each resample draws ``runs`` runs with replacement; the interval is the
    ``(1 - confidence) / 2`` and ``(1 + confidence) / 2`` quantiles of the resampled means (per
    point). One run gives a zero-width interval at its value: with one seed there is no spread
    to measure. Returns floats for 1-D input, arrays of shape ``(points,)`` for 2-D.
    """
    x = np.asarray(values, dtype=float)
    if x.ndim not in (1, 2) or x.shape[0] == 0:
        raise ValueError(f"bootstrap_ci: expected (runs,) or (runs, points) with runs >= 1, got shape {x.shape}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"bootstrap_ci: confidence must be in (0, 1), got {confidence}")
    n = x.shape[0]
    rng = np.random.default_rng(seed)
    # How often each run is drawn in each resample: the resampled mean is counts @ x / n.
    counts = rng.multinomial(n, np.full(n, 1.0 / n), size=resamples).astype(float)
    means = counts @ x.reshape(n, -1) / n  # (resamples, points)
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(means, [alpha, 1.0 - alpha], axis=0)
    # The quantiles of identical means can differ from them by a rounding error: clip to the data.
    lo = np.clip(lo, x.min(axis=0), None)
    hi = np.clip(hi, None, x.max(axis=0))
    if x.ndim == 1:
        return float(lo[0]), float(hi[0])
    return lo, hi


def paired_difference_ci(a: Sequence[Sequence[float]] | np.ndarray, b: Sequence[Sequence[float]] | np.ndarray,
                         confidence: float = 0.95, resamples: int = RESAMPLES, seed: int = SEED) -> tuple[float, float]:
    """Percentile bootstrap interval of ``mean(a) - mean(b)`` for two groups of runs on the same episodes.

    ``a``, ``b``: one row per run, one column per episode (an outcome such as 0/1 achieved), the columns the same
    episodes in the same order. Each resample draws the episodes with replacement (the same draw for both groups:
    they are paired) and, within each group, its runs with replacement. A group of one run (the scripted driver) is
    resampled over its episodes only.
    """
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] == 0 or y.shape[0] == 0 or x.shape[1] != y.shape[1] or not x.shape[1]:
        raise ValueError(f"paired_difference_ci: expected (runs, episodes) arrays over the same episodes, got "
                         f"shapes {x.shape} and {y.shape}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"paired_difference_ci: confidence must be in (0, 1), got {confidence}")
    rng = np.random.default_rng(seed)
    episodes = x.shape[1]
    diffs = np.empty(resamples)
    for i in range(resamples):
        eps = rng.integers(0, episodes, episodes)
        xa = x[rng.integers(0, x.shape[0], x.shape[0])][:, eps].mean()
        yb = y[rng.integers(0, y.shape[0], y.shape[0])][:, eps].mean()
        diffs[i] = xa - yb
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(diffs, [alpha, 1.0 - alpha])
    return float(lo), float(hi)


def common_range(xs: Sequence[np.ndarray]) -> tuple[float, float] | None:
    """The x range every run covers: (latest start, earliest end), or None if they do not overlap
    (or a run has no points)."""
    if not xs or any(len(x) == 0 for x in xs):
        return None
    start, end = max(float(np.min(x)) for x in xs), min(float(np.max(x)) for x in xs)
    return (start, end) if start <= end else None


def curves_on_grid(xs: Sequence[np.ndarray], ys: Sequence[np.ndarray], points: int = 200,
                   confidence: float = 0.95, resamples: int = RESAMPLES, seed: int = SEED) -> dict[str, np.ndarray]:
    """Per-run curves (``xs[i]`` non-decreasing, ``ys[i]`` the run's smoothed value there) on a
    common grid of ``points`` x values spanning the range every run covers, each run linearly
    interpolated onto it. Returns ``{"x", "mean", "lo", "hi", "runs"}``: the grid, the mean over
    runs, the bootstrap band (:func:`bootstrap_ci`) and the interpolated runs ``(runs, points)``;
    all empty when the runs share no range."""
    if len(xs) != len(ys):
        raise ValueError(f"curves_on_grid: {len(xs)} x arrays but {len(ys)} y arrays")
    xs = [np.asarray(x, dtype=float) for x in xs]
    ys = [np.asarray(y, dtype=float) for y in ys]
    for x, y in zip(xs, ys):
        if x.shape != y.shape or x.ndim != 1:
            raise ValueError(f"curves_on_grid: each run's x and y must be 1-D of one length, got {x.shape}, {y.shape}")
    span = common_range(xs)
    if span is None:
        empty = np.zeros(0)
        return {"x": empty, "mean": empty, "lo": empty, "hi": empty, "runs": np.zeros((len(xs), 0))}
    grid = np.linspace(span[0], span[1], points if span[1] > span[0] else 1)
    runs = np.stack([np.interp(grid, x, y) for x, y in zip(xs, ys)])
    lo, hi = bootstrap_ci(runs, confidence, resamples, seed)
    return {"x": grid, "mean": runs.mean(axis=0), "lo": lo, "hi": hi, "runs": runs}


def drop_noise_floor(rate: float, episodes: int, evaluations: int, target: float,
                     draws: int = 20_000, seed: int = 0) -> dict[str, float] | None:
    """The largest drop below the running best (after the first evaluation at or above ``target``,
    as the protocol's stability column measures it) that a policy whose true rate never changes
    shows, only because each evaluation counts ``episodes`` episodes: the median and the 90th
    percentile over ``draws`` simulated runs of ``evaluations`` binomial(episodes, rate) scores, and
    the share of them above 5 points. None when no simulated run reaches ``target``.

    It tells a measured drop from evaluation noise: at a true 96 %, 20-episode evaluations drop by
    a median 10 points though nothing changed; 200-episode ones by 3.5.
    """
    rng = np.random.default_rng(seed)
    scores = rng.binomial(episodes, rate, size=(draws, evaluations)) / episodes
    reached = scores >= target - 1e-12
    first = np.where(reached.any(axis=1), reached.argmax(axis=1), evaluations)
    masked = np.where(np.arange(evaluations)[None, :] >= first[:, None], scores, -np.inf)
    best = np.maximum.accumulate(masked, axis=1)
    drops = np.where(np.isfinite(masked), best - scores, 0.0).max(axis=1)[first < evaluations]
    if drops.size == 0:
        return None
    return {"median": round(float(np.median(drops)), 4), "p90": round(float(np.quantile(drops, 0.9)), 4),
            "share_above_5_points": round(float((drops > 0.05 + 1e-9).mean()), 4)}
