"""Stacked image observations stored once per frame, not once per stack position.

A grayscale observation is a stack ``(S, H, W)`` of the last S frames (newest last), and the
next observation shares S - 1 of them; so do the next S - 1 items of the same actor. Storing
``obs`` and ``next_obs`` as whole stacks keeps every frame 2 S times (8 with S = 4): 80 KB per
item for 4 x 100 x 100, 8 GB for a table of 100,000. Here each item holds 2 S frame *keys*
into one ring of single frames, and a sample gathers its stacks from it.

- ``FrameStore``: the ring of frames. Keys are global insertion counters; a frame's slot is
  ``key % capacity``.
- ``FrameRingTable``: the online FIFO table (``storage.RingTable``'s interface) with frame keys
  in place of the two stack columns. On insert, each frame of a row is looked up among the
  sending actor's recent frames (crc32, then compared byte for byte, so a hash collision can
  never return a wrong frame) and stored only if new. Items live while all their frames do:
  when the frame ring wraps, the oldest items go first, which keeps eviction FIFO (see
  ``frame_floor``). Steady state is about one new frame per item, whatever the n-step length,
  the number of interleaved actors or the spacing of the stacked frames (``env.frame_interval``),
  so the default frame ring (``replay.frames_per_item`` = 2 frames per item of capacity) holds
  the whole table; a run that needs more (short episodes) evicts early, and the stats say how
  many items went that way (``evicted_for_frames``).
- ``dedup_stacks``: the same for a fixed set of stacks (the demo table), done once at load.

Room: replay_server (component). May import: numpy, zlib, the contract (laneshift.wire), and .storage.
"""

from __future__ import annotations

import collections
import zlib

import numpy as np

from laneshift.wire import TransitionBatch

from .storage import RingTable

#: A sending actor's frames remembered for reuse. An item's frames span its stack's reach, (S - 1)
#: x env.frame_interval steps back, and its next observation's, n steps ahead: 2 x (3 x 30 + 10)
#: frames at the widest settings, so this holds them with room to spare.
RECENT_FRAMES = 256
#: A frame is reused only while it lies in the newest 1 / REUSE_WINDOW of the frame ring. Each row
#: then has a lower bound on its frame keys (``frame_floor``) that never goes down from row to row,
#: however the actors interleave, so the rows a wrapping ring must drop are always the oldest.
#: (Inserts go in chunks of at most half the ring, so a reused frame outlives the chunk's writes.)
REUSE_WINDOW = 4


class FrameStore:
    """A ring of single frames ``[capacity, H, W]`` addressed by global keys."""

    def __init__(self, capacity: int, frame_shape: tuple[int, ...], dtype: str):
        self.capacity = int(capacity)
        self.frames = np.zeros((self.capacity, *frame_shape), dtype)
        self.key = np.full(self.capacity, -1, np.int64)  # which frame each slot holds (-1: none)
        self.inserted = 0

    def holds(self, keys: np.ndarray) -> np.ndarray:
        return self.key[keys % self.capacity] == keys

    def gather(self, keys: np.ndarray) -> np.ndarray:
        """``keys [..., S]`` -> frames ``[..., S, H, W]`` (a copy)."""
        return self.frames[keys % self.capacity]

    @property
    def nbytes(self) -> int:
        return self.frames.nbytes + self.key.nbytes


class StackView:
    """Read-only ``table.obs``-like access to stacks held as frame keys: ``view[rows]`` gathers."""

    def __init__(self, store: FrameStore, keys: np.ndarray):
        self.store, self.keys = store, keys

    def __getitem__(self, rows) -> np.ndarray:
        return self.store.gather(self.keys[rows])

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """What holds it (DemoTable's digest, size and read-only flags use these)."""
        return self.store.frames, self.keys

    def subset(self, rows: np.ndarray) -> "StackView":
        """The stacks of ``rows``, over the same frames (no frame copied)."""
        return StackView(self.store, self.keys[rows])


def fixed_stack_views(obs: np.ndarray, next_obs: np.ndarray) -> tuple[StackView, StackView]:
    """Views over one frame store holding each distinct frame of ``obs``/``next_obs`` once."""
    frames, obs_keys, next_keys = dedup_stacks(obs, next_obs)
    store = FrameStore(len(frames), frames.shape[1:], str(frames.dtype))
    store.frames[:] = frames
    store.key[:] = np.arange(len(frames))
    store.inserted = len(frames)
    return StackView(store, obs_keys), StackView(store, next_keys)


class FrameRingTable(RingTable):
    """The online FIFO table for stacked frames: ``obs``/``next_obs`` are views over a FrameStore."""

    def __init__(self, capacity: int, obs_shape: tuple[int, ...], obs_dtype: str, frames_per_item: float = 2.0):
        stack = obs_shape[0]
        super().__init__(capacity, (0,), obs_dtype)  # the stack columns are replaced below
        frames = max(int(round(capacity * frames_per_item)), 16 * stack)  # at least a few rows per chunk (insert)
        self.store = FrameStore(frames, tuple(obs_shape[1:]), obs_dtype)
        self.obs_key = np.zeros((self.capacity, stack), np.int64)
        self.next_key = np.zeros((self.capacity, stack), np.int64)
        self.obs, self.next_obs = StackView(self.store, self.obs_key), StackView(self.store, self.next_key)
        self.records = None  # the stacks are not in the records: a sample gathers column by column
        self._tail = 0  # key of the oldest live item
        # Each row's frame keys are all >= its frame_floor, and frame_floor never goes down from an
        # item to the next (by key), so when the frame ring wraps the items to drop are a prefix.
        # (A bound by time, not the row's own oldest frame: with two actors interleaved, or frames
        # spaced k steps apart, a row's oldest frame can be older than the previous row's, and a
        # floor made of those would forbid reusing it: about 7 frames an item were stored then.)
        self.frame_floor = np.zeros(self.capacity, np.int64)
        self._recent: dict[int, collections.OrderedDict[int, int]] = collections.defaultdict(collections.OrderedDict)
        self.evicted_for_frames = 0  # items dropped before the table was full, their frames overwritten
        self.frames_stored = 0  # frames written (the rest of 2 S per item were shared)

    @property
    def tail(self) -> int:
        return self._tail

    @property
    def size(self) -> int:
        return self.inserted - self._tail

    @property
    def nbytes(self) -> int:
        cols = (self.obs_key, self.next_key, self.frame_floor, self.action, self.reward, self.terminated,
                self.truncated, self.steps, self.actor, self.version, self.key, self.seq)
        return sum(a.nbytes for a in cols) + self.store.nbytes

    def insert(self, batch: TransitionBatch, actor_index: int) -> np.ndarray:
        n = len(batch)
        skip = max(0, n - self.capacity)  # a batch larger than the table keeps its newest rows
        # Rows go in chunks whose frames, all new at worst, fit the frame ring twice over: a frame
        # reused by a chunk then outlives the chunk's own writes.
        chunk = max(1, self.store.capacity // (4 * self.obs_key.shape[1]))
        for begin in range(skip, n, chunk):
            self._insert_rows(batch, begin, min(n, begin + chunk), actor_index)
        keys = np.arange(self.inserted - (n - skip), self.inserted, dtype=np.int64)
        return keys

    def _frame_keys(self, batch: TransitionBatch, begin: int, end: int, actor_index: int,
                    reuse_from: int) -> tuple[np.ndarray, list]:
        """Frame keys of rows ``begin:end`` (``[rows, 2 S]``: obs, then next_obs) and the new frames;
        frames older than ``reuse_from`` (the rows' floor) are stored again rather than reused."""
        store, stack = self.store, self.obs_key.shape[1]
        recent = self._recent[actor_index]
        new_frames: list[np.ndarray] = []
        keys_of = np.empty((end - begin, 2 * stack), np.int64)
        for i in range(end - begin):
            row = np.concatenate([batch.obs[begin + i], batch.next_obs[begin + i]])
            for j, frame in enumerate(row):
                fp = zlib.crc32(frame)
                k = recent.get(fp)
                if k is not None and k >= reuse_from:
                    held = (new_frames[k - store.inserted] if k >= store.inserted
                            else store.frames[k % store.capacity] if store.key[k % store.capacity] == k else None)
                    if held is not None and np.array_equal(held, frame):
                        keys_of[i, j] = k
                        recent.move_to_end(fp)
                        continue
                k = store.inserted + len(new_frames)
                new_frames.append(frame)
                recent[fp] = k
                recent.move_to_end(fp)
                if len(recent) > RECENT_FRAMES:
                    recent.popitem(last=False)
                keys_of[i, j] = k
        return keys_of, new_frames

    def _reuse_from(self) -> int:
        """The oldest frame key the next rows may reuse: their ``frame_floor`` (never below the newest
        row's)."""
        newest = self.frame_floor[(self.inserted - 1) % self.capacity] if self.inserted else 0
        return max(int(newest), self.store.inserted - self.store.capacity // REUSE_WINDOW)

    def _insert_rows(self, batch: TransitionBatch, begin: int, end: int, actor_index: int) -> None:
        store, stack = self.store, self.obs_key.shape[1]
        floor = self._reuse_from()
        keys_of, new_frames = self._frame_keys(batch, begin, end, actor_index, floor)
        keys = np.arange(self.inserted, self.inserted + end - begin, dtype=np.int64)
        # Drop the items the table's capacity pushes out, then those whose frames the new frames
        # may overwrite: a prefix of the live items, since their frame floors rise with their keys.
        first_kept_frame = store.inserted + len(new_frames) - store.capacity
        tail = full_tail = max(self._tail, int(keys[-1]) + 1 - self.capacity)
        while tail < self.inserted and self.frame_floor[tail % self.capacity] < first_kept_frame:
            tail += 1
        self.evicted_for_frames += tail - full_tail
        self._tail = tail
        if new_frames:
            fkeys = np.arange(store.inserted, store.inserted + len(new_frames))
            store.frames[fkeys % store.capacity] = np.stack(new_frames)
            store.key[fkeys % store.capacity] = fkeys
            store.inserted += len(new_frames)
            self.frames_stored += len(new_frames)
        rows = keys % self.capacity
        self.obs_key[rows], self.next_key[rows] = keys_of[:, :stack], keys_of[:, stack:]
        self.frame_floor[rows] = floor
        for name in ("action", "reward", "terminated", "truncated", "steps"):
            getattr(self, name)[rows] = getattr(batch, name)[begin:end]
        self.actor[rows] = actor_index
        self.version[rows] = batch.weights_version
        self.key[rows] = keys
        self.seq[rows] = batch.seq
        self.inserted += end - begin

    def restored(self, n: int) -> None:
        """Rows 0..n-1 were just written back from a checkpoint (oldest first): each row's frame
        floor is the oldest frame of it and of every later row, which never goes down from a row
        to the next and bounds the row's frames (the checkpoint need not hold the floors)."""
        if n:
            oldest = np.minimum(self.obs_key[:n].min(axis=1), self.next_key[:n].min(axis=1))
            self.frame_floor[:n] = np.minimum.accumulate(oldest[::-1])[::-1]

    def forget_actor(self, actor_index: int) -> None:
        """An evicted actor's recent frames are not reused by the next actor given its index."""
        self._recent.pop(actor_index, None)


def dedup_stacks(obs: np.ndarray, next_obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed stacks ``[N, S, H, W]`` (twice) -> ``(frames [F, H, W], obs_keys [N, S], next_keys [N, S])``
    with every distinct frame once (equal bytes, checked; crc32 only finds candidates)."""
    n, stack = obs.shape[:2]
    frames: list[np.ndarray] = []
    seen: dict[int, list[int]] = {}
    keys = np.empty((2, n, stack), np.int64)
    for which, stacks in enumerate((obs, next_obs)):
        for i in range(n):
            for j in range(stack):
                frame = stacks[i, j]
                candidates = seen.setdefault(zlib.crc32(np.ascontiguousarray(frame)), [])
                for k in candidates:
                    if np.array_equal(frames[k], frame):
                        break
                else:
                    k = len(frames)
                    frames.append(frame)
                    candidates.append(k)
                keys[which, i, j] = k
    shape = obs.shape[2:]
    stored = np.stack(frames) if frames else np.zeros((0, *shape), obs.dtype)
    return stored, keys[0], keys[1]
