"""n-step returns (DQfD, Rainbow): one item per step, carrying the next ``n`` rewards.

An item is ``(obs_t, a_t, R, obs_{t+k}, terminated, k)`` with ``R = sum_{i<k} gamma^i r_{t+i}``
and ``k = n`` except where the episode ended sooner. The learner's target is ``R + gamma^k *
(1 - terminated) * Q(obs_{t+k}, .)``: no value after a crash, while a time-limit truncation still
bootstraps from the last observation. With ``n = 1`` the items are the ordinary transitions
(``k = 1``), so the wire carries ``k`` per item (``steps``) and 1-step actors need nothing new.

Numpy and stdlib only: actors build items online (:class:`NStepAccumulator`), the replay server
converts whole demo shards (:func:`nstep_arrays`), and both give the same items (tested).

    >>> acc = NStepAccumulator(n=2, gamma=0.5)
    >>> acc.push(0, 1, 1.0, 10, False, False)
    []
    >>> [(it.obs, it.reward, it.next_obs, it.steps) for it in acc.push(10, 1, 2.0, 20, True, False)]
    [(0, 2.0, 20, 2), (10, 2.0, 20, 1)]

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

from collections import deque
from typing import Any, NamedTuple

import numpy as np


class NStepItem(NamedTuple):
    obs: Any
    action: int
    reward: float  # discounted sum of up to n rewards
    next_obs: Any  # the observation the bootstrap value is taken at
    steps: int  # k: rewards summed, the bootstrap is discounted by gamma^k
    terminated: bool  # the episode terminated inside the window (no bootstrap)
    truncated: bool  # the episode was truncated inside the window


#: Largest n (the wire carries k as uint8).
MAX_NSTEP = 255


def check_nstep(n: int, gamma: float) -> None:
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_NSTEP:
        raise ValueError(f"n_step must be an int in [1, {MAX_NSTEP}], got {n!r}")
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must be in [0, 1], got {gamma!r}")


class NStepAccumulator:
    """Turns one env's stream of steps into n-step items (one per step, delayed by up to n - 1)."""

    def __init__(self, n: int, gamma: float):
        check_nstep(n, gamma)
        self.n, self.gamma = n, float(gamma)
        self._window: deque[tuple[Any, int, float]] = deque()

    def __len__(self) -> int:
        return len(self._window)

    def push(self, obs: Any, action: int, reward: float, next_obs: Any, terminated: bool,
             truncated: bool) -> list[NStepItem]:
        """Add one env step; returns the items it completes (all pending ones at an episode end)."""
        self._window.append((obs, int(action), float(reward)))
        if terminated or truncated:
            return self._drain(next_obs, terminated=bool(terminated), truncated=bool(truncated))
        if len(self._window) == self.n:
            return [self._pop(next_obs, terminated=False, truncated=False)]
        return []

    def flush(self, next_obs: Any) -> list[NStepItem]:
        """Items of an unfinished episode (the worker's budget ran out): they bootstrap from
        ``next_obs``, the latest observation, exactly as a truncation does."""
        return self._drain(next_obs, terminated=False, truncated=False)

    def _drain(self, next_obs: Any, terminated: bool, truncated: bool) -> list[NStepItem]:
        out = []
        while self._window:
            out.append(self._pop(next_obs, terminated, truncated))
        return out

    def _pop(self, next_obs: Any, terminated: bool, truncated: bool) -> NStepItem:
        k = len(self._window)
        ret = 0.0
        for i, (_, _, r) in enumerate(self._window):
            ret += self.gamma**i * r
        obs, action, _ = self._window.popleft()
        return NStepItem(obs, action, ret, next_obs, k, terminated, truncated)


def nstep_arrays(reward: np.ndarray, next_obs: np.ndarray, terminated: np.ndarray, episode_ids: np.ndarray,
                 n: int, gamma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """n-step versions of flat 1-step transitions stored episode after episode.

    Returns ``(reward_n, next_obs_n, terminated_n, steps)``. An episode is a run of equal
    ``episode_ids``; one that ends without ``terminated`` (time limit, or cut short) bootstraps from
    its last ``next_obs``.
    """
    check_nstep(n, gamma)
    size = int(reward.shape[0])
    for name, arr in (("next_obs", next_obs), ("terminated", terminated), ("episode_ids", episode_ids)):
        if arr.shape[0] != size:
            raise ValueError(f"{name} has {arr.shape[0]} rows, reward has {size}")
    reward = np.asarray(reward, np.float64)
    terminated = np.asarray(terminated, bool)
    # Last row of each episode, for every row.
    boundary = np.ones(size, bool)
    boundary[:-1] = episode_ids[1:] != episode_ids[:-1]
    ends = np.flatnonzero(boundary)
    episode_end = ends[np.searchsorted(ends, np.arange(size))] if size else np.zeros(0, np.int64)
    last = np.minimum(np.arange(size) + n - 1, episode_end)  # the window's last row
    steps = last - np.arange(size) + 1
    ret = np.zeros(size)
    for i in range(n):
        rows = np.arange(size) + i
        live = i < steps
        ret[live] += gamma**i * reward[rows[live]]
    term = terminated[last] & (last == episode_end)
    return ret.astype(np.float32), next_obs[last], term.astype(np.uint8), steps.astype(np.uint8)
