"""Preallocated numpy tables: the online FIFO ring and the fixed demo table.

Memory is allocated once at start (``capacity`` rows), so it stays bounded whatever the
actors' or the learner's speed; inserting is a vectorised copy with wrap-around.

    >>> t = RingTable(4, obs_shape=(2,), obs_dtype="float32")
    >>> t.size
    0

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from laneshift.wire import TransitionBatch


def record_dtype(obs_shape: tuple[int, ...], obs_dtype: str) -> np.dtype:
    """The fields a sample reads of one row, held side by side (``RingTable.records``).

    A sample reads 256 random rows. Held as separate columns, each row costs a cache miss per
    column; held as one record (672 bytes for an 82-float observation) it is one contiguous span,
    which the hardware prefetcher follows. One ``np.take`` of 256 such records took 32 us against
    62-71 us for the column gathers (400k rows, 2026-11-24).
    """
    return np.dtype([("obs", obs_dtype, obs_shape), ("next_obs", obs_dtype, obs_shape), ("action", "<i8"),
                     ("reward", "<f4"), ("terminated", "|u1"), ("steps", "|u1")], align=True)


class RingTable:
    """FIFO ring of transitions. Item keys are global insertion counters (monotone).

    The fields a sample reads live in one record per row (``records``); ``obs``, ``action`` and
    the others are views of its fields, so every other reader and writer sees plain columns.
    """

    def __init__(self, capacity: int, obs_shape: tuple[int, ...], obs_dtype: str):
        self.capacity = int(capacity)
        # Zeros, and left so: pages are only touched as rows are written (a 100k table is 67 MB;
        # a short run fills a fraction of it). A row never written has steps 0 and is never sampled.
        rec = np.zeros(self.capacity, record_dtype(tuple(obs_shape), obs_dtype))
        self.records: np.ndarray | None = rec
        self.obs, self.next_obs, self.action, self.reward = rec["obs"], rec["next_obs"], rec["action"], rec["reward"]
        self.terminated = rec["terminated"]
        self.steps = rec["steps"]  # n-step: rewards summed in `reward`
        self.truncated = np.zeros(self.capacity, np.uint8)
        self.actor = np.zeros(self.capacity, np.int16)  # index into the server's actor list
        self.version = np.zeros(self.capacity, np.int64)  # weights version that acted
        self.key = np.full(self.capacity, -1, np.int64)  # each row's item key (-1: empty)
        self.seq = np.full(self.capacity, -1, np.int64)  # the actor's batch seq the item came in
        self.inserted = 0  # total items ever inserted (the next item's key)

    @property
    def size(self) -> int:
        return min(self.inserted, self.capacity)

    @property
    def tail(self) -> int:
        """Key of the oldest live item; live keys are ``tail .. inserted - 1``, in ``size`` rows."""
        return self.inserted - self.size

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.records, self.truncated, self.actor, self.version, self.key, self.seq))

    def insert(self, batch: TransitionBatch, actor_index: int) -> np.ndarray:
        """Store a validated batch; returns the keys of the items stored."""
        n = len(batch)
        skip = max(0, n - self.capacity)  # a batch larger than the table keeps its newest rows
        keys = np.arange(self.inserted + skip, self.inserted + n, dtype=np.int64)
        # The rows are consecutive modulo the capacity: at most two slice copies per column (a
        # fancy-index scatter per column cost 8x more per 32-row batch).
        start = (self.inserted + skip) % self.capacity
        first = min(n - skip, self.capacity - start)
        for dst, src in ((slice(start, start + first), slice(skip, skip + first)),
                         (slice(0, n - skip - first), slice(skip + first, n))):
            if dst.stop <= dst.start:
                continue
            self.obs[dst] = batch.obs[src]
            self.next_obs[dst] = batch.next_obs[src]
            self.action[dst] = batch.action[src]
            self.reward[dst] = batch.reward[src]
            self.terminated[dst] = batch.terminated[src]
            self.truncated[dst] = batch.truncated[src]
            self.steps[dst] = batch.steps[src]
            self.actor[dst] = actor_index
            self.version[dst] = batch.weights_version
            self.key[dst] = keys[src.start - skip:src.stop - skip]
            self.seq[dst] = batch.seq
        self.inserted += n
        return keys

    def rows_of(self, keys: np.ndarray) -> np.ndarray:
        return keys % self.capacity

    def valid(self, keys: np.ndarray) -> np.ndarray:
        """Which keys still refer to stored (not yet evicted) items."""
        return (keys >= self.tail) & (keys < self.inserted)

    def live_keys(self) -> np.ndarray:
        return np.arange(self.tail, self.inserted, dtype=np.int64)


@dataclass
class DemoTable:
    """The demo shard's transitions, loaded once and never evicted or modified."""

    obs: np.ndarray  # or a frames.StackView: stacked images held once per frame
    action: np.ndarray
    reward: np.ndarray
    next_obs: np.ndarray  # likewise
    terminated: np.ndarray
    sha256: str
    metadata: dict
    steps: np.ndarray | None = None  # n-step: rewards summed in `reward` (None: all 1)

    def __post_init__(self) -> None:
        if self.steps is None:
            self.steps = np.ones(self.size, np.uint8)
        for arr in self._arrays():
            arr.flags.writeable = False  # a bug elsewhere must not be able to corrupt the demos

    @property
    def size(self) -> int:
        return int(self.action.shape[0])

    def _arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays that hold the table. ``obs``/``next_obs`` may be views over shared frames
        (``frames.StackView``: stacked images kept once per frame); those give their arrays."""
        out: dict[int, np.ndarray] = {}
        for col in (self.obs, self.action, self.reward, self.next_obs, self.terminated, self.steps):
            for arr in getattr(col, "arrays", (col,)):
                out.setdefault(id(arr), arr)  # the frames obs and next_obs share count once
        return tuple(out.values())

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self._arrays())

    def digest(self) -> str:
        """sha256 over the table's arrays as held in memory (to prove nothing was changed)."""
        import hashlib

        h = hashlib.sha256()
        for arr in self._arrays():
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()

    def subset(self, rows: np.ndarray) -> "DemoTable":
        pick = (lambda col: col.subset(rows)) if hasattr(self.obs, "subset") else (lambda col: col[rows])
        return DemoTable(pick(self.obs), self.action[rows], self.reward[rows], pick(self.next_obs),
                         self.terminated[rows], self.sha256, self.metadata, self.steps[rows])

    @classmethod
    def empty(cls, obs_shape: tuple[int, ...], obs_dtype: str) -> "DemoTable":
        z = np.zeros((0, *obs_shape), obs_dtype)
        return cls(z, np.zeros(0, np.int64), np.zeros(0, np.float32), z.copy(), np.zeros(0, np.uint8), "", {})
