"""What the two array messages carry: ``TransitionSchema`` (what a run's observations and actions
look like), ``TransitionBatch`` (TRANSITIONS: an actor's rows to the replay server) and
``SampledBatch`` (BATCH: the replay server's sampled rows to the learner). Data only: the codecs
are in ``.transitions``, ``.sampling`` and ``.fastpath``, which all build these.

Room: the contract (shared by every process). May import: numpy, the standard library and
``.envelope`` (the row limit).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .envelope import MAX_BATCH_ROWS


@dataclass(frozen=True)
class TransitionSchema:
    """What a run's transitions look like; the replay server validates every batch against it."""

    obs_shape: tuple[int, ...]
    obs_dtype: str
    n_actions: int
    max_rows: int = MAX_BATCH_ROWS

    def __post_init__(self) -> None:
        object.__setattr__(self, "obs_shape", tuple(int(d) for d in self.obs_shape))
        object.__setattr__(self, "obs_dtype", np.dtype(self.obs_dtype).str)


@dataclass(frozen=True)
class TransitionBatch:
    """B transitions from one actor, produced under one weights version."""

    actor: str
    seq: int  # per-actor message counter, starts at 0
    weights_version: int  # the weights version that chose these actions
    phase: int  # rehearsal phase the actor was in (0 when not rehearsing)
    env_steps: int  # the actor's cumulative env steps after this batch
    obs: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    # Rewards summed in `reward` (n-step returns, laneshift.nstep): the learner discounts the
    # bootstrap value at next_obs by gamma ** steps. 1 for ordinary transitions.
    steps: np.ndarray | None = None
    extra: dict = field(default_factory=dict)  # free-form JSON fields (e.g. episode ids)

    def __post_init__(self) -> None:
        if self.steps is None:
            object.__setattr__(self, "steps", np.ones(len(self), np.uint8))

    @classmethod
    def from_arrays(cls, **kw: Any) -> "TransitionBatch":
        kw["action"] = np.asarray(kw["action"], dtype=np.int64)
        kw["reward"] = np.asarray(kw["reward"], dtype=np.float32)
        kw["terminated"] = np.asarray(kw["terminated"], dtype=np.uint8)
        kw["truncated"] = np.asarray(kw["truncated"], dtype=np.uint8)
        if kw.get("steps") is not None:
            kw["steps"] = np.asarray(kw["steps"], dtype=np.uint8)
        return cls(**kw)

    def __len__(self) -> int:
        return int(self.action.shape[0])


@dataclass(frozen=True, kw_only=True)  # keyword-only: next_obs defaults to None where it stands
class SampledBatch:
    """``num_batches * batch_size`` rows; split with ``np.split(..., num_batches)``."""

    obs: np.ndarray
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray | None = None  # None: the request asked for none (SampleRequest.next_obs=False)
    terminated: np.ndarray
    steps: np.ndarray  # rewards summed per row: the bootstrap is discounted by gamma ** steps
    is_demo: np.ndarray  # 1 where the row came from the demo shard
    index: np.ndarray  # item keys, for priority updates
    weight: np.ndarray  # importance-sampling weights (1 for uniform sampling)
    num_batches: int = 1
    info: dict = field(default_factory=dict)


BATCH_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "steps", "is_demo", "index", "weight")
