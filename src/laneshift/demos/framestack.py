"""Store stacked grayscale observations once per frame instead of once per stack position.

highway-env's grayscale observation is a stack ``(S, W, H)`` whose newest frame is last and
whose older frames are the previous observation shifted by one (``np.roll`` + new frame).
Consecutive observations of an episode therefore share ``S - 1`` frames, and storing whole
stacks writes every frame ``S`` times. An episode of ``T`` steps has ``T + 1`` observations;
it is stored as

* ``frames``: ``[T + 1, W, H]`` the newest frame of every observation, and
* ``prefix``: ``[S - 1, W, H]`` the older frames of the first (reset) observation,

and rebuilt exactly on load: observation ``t`` is ``concat(prefix, frames)[t : t + S]``.
The split is only used when it is exact (checked frame by frame); otherwise the caller keeps
full stacks.

Example::

    >>> import numpy as np
    >>> seq = np.arange(6 * 2 * 2, dtype=np.uint8).reshape(6, 2, 2)
    >>> stacks = np.stack([seq[t:t + 3] for t in range(4)])          # [4, 3, 2, 2]
    >>> prefix, frames = split_frame_stacks(stacks)
    >>> bool(np.array_equal(rebuild_frame_stacks(prefix, frames), stacks))
    True

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view


def split_frame_stacks(observations: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Split one episode's stacked observations ``[T+1, S, W, H]`` into ``(prefix, frames)``.

    Returns None when the observations are not a shifting frame stack (wrong rank, a single
    frame per stack, or some step that is not "previous stack shifted by one + new frame").
    """
    if observations.ndim != 4 or observations.shape[1] < 2 or len(observations) == 0:
        return None
    if not np.array_equal(observations[1:, :-1], observations[:-1, 1:]):
        return None
    prefix = np.ascontiguousarray(observations[0, :-1])
    frames = np.ascontiguousarray(observations[:, -1])
    return prefix, frames


def rebuild_frame_stacks(prefix: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Inverse of :func:`split_frame_stacks`: ``[S-1, W, H]`` + ``[T+1, W, H]`` -> ``[T+1, S, W, H]``.

    The result is a read-only strided view (no copy); copy it if you need to write to it.
    """
    if prefix.shape[1:] != frames.shape[1:] or prefix.dtype != frames.dtype:
        raise ValueError(
            f"frame prefix {prefix.shape} {prefix.dtype} does not match frames "
            f"{frames.shape} {frames.dtype}"
        )
    stack = len(prefix) + 1
    sequence = np.concatenate([prefix, frames], axis=0)
    windows = sliding_window_view(sequence, stack, axis=0)  # [T+1, W, H, S]
    return np.moveaxis(windows, -1, 1)
