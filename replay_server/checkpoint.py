"""Checkpoints of the online table that never stop inserts or samples for long.

A checkpoint copies the ring in chunks; each chunk is copied under the core's lock (about a
millisecond), and the lock is released between chunks, so actors and the learner keep going
while it runs. It holds the table as it was at its *cut*: the instant it starts, under the lock,
it reads the insert counter (every row carries its item's key, the insertion counter) and the
per-actor counters, and restore keeps only the items with keys below the cut. Items stored while
the copy runs (the copy may catch any part of them) are not in it: with the write-ahead log
(``wal.py``, ``replay.wal``) they are in the log's segments from the one the checkpoint started at
the cut (``wal_from`` in meta.json), which a restart replays after the restore; without it they
are lost and counted (each actor resumes after its last batch before the cut, so every later
batch is a seq gap). So every item is either restored or counted. (Before format 3 the counters
were read after the copy, and a batch the copy caught in part beside a later one it caught whole
was neither restored nor counted.)

The files go to a temp directory that is renamed over the previous checkpoint at the end, so a
crash (even kill -9) leaves either the old or the new checkpoint, never a torn one; the log
segments the new one holds are deleted only after the rename.

The demo table is not checkpointed: it is reloaded from its shard, whose sha256 is verified.

A table of stacked frames (``frames.FrameRingTable``) has ``obs_key`` / ``next_key`` in place of
``obs`` / ``next_obs``, and its frame ring in ``frames.npy`` + ``frame_key.npy``, copied after the
rows (frames with keys from the cut on are left out). Frames overwritten between the two copies
belong to the oldest items (the ring is FIFO); restore drops those items as the ring would have,
and keeps every item whose frames are all there.

Layout of ``<run dir>/replay_checkpoint/``: one ``.npy`` per column (``obs``, ``next_obs``,
``action``, ``reward``, ``terminated``, ``truncated``, ``steps``, ``actor``, ``version``, ``seq``,
``key``) and ``meta.json`` (format version, schema, the cut, counters, per-actor stats and the
seqs still fillable (``gaps``) at the cut, ``wal_from``).

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .frames import FrameRingTable

if TYPE_CHECKING:  # pragma: no cover
    from .core import ReplayCore

FORMAT = 3  # 2: the steps column (n-step returns); 3: the cut (items, counters as of the start), wal_from
COLUMNS = ("obs", "next_obs", "action", "reward", "terminated", "truncated", "steps", "actor", "version", "seq", "key")
FRAME_COLUMNS = ("obs_key", "next_key") + COLUMNS[2:]
CHUNK_BYTES = 4 * 2**20  # rows copied per lock hold: ~4 MiB


def _columns(table) -> tuple[str, ...]:
    return FRAME_COLUMNS if isinstance(table, FrameRingTable) else COLUMNS


def _copy_chunked(core: "ReplayCore", arrays: dict[str, np.ndarray], files: dict) -> np.ndarray:
    """Write ``arrays`` (same length) into ``files`` as .npy, a chunk per lock hold; returns the
    last column's values (the keys) as copied."""
    for name, f in files.items():
        col = arrays[name]
        np.lib.format.write_array_header_1_0(f, {"descr": np.lib.format.dtype_to_descr(col.dtype),
                                                 "fortran_order": False, "shape": col.shape})
    row_bytes = sum(a.dtype.itemsize * int(np.prod(a.shape[1:], dtype=np.int64)) for a in arrays.values())
    chunk = max(1, CHUNK_BYTES // max(row_bytes, 1))
    length = len(next(iter(arrays.values())))
    last = list(arrays)[-1]
    copied = []
    for begin in range(0, length, chunk):
        end = min(begin + chunk, length)
        with core.lock:  # short: one chunk copied to memory, then inserts and samples go on
            parts = {name: arr[begin:end].copy() for name, arr in arrays.items()}
        copied.append(parts[last])
        for name, part in parts.items():
            files[name].write(part.tobytes())
    return np.concatenate(copied) if copied else np.zeros(0, np.int64)


class CheckpointError(ValueError):
    pass


class CutLog(Protocol):
    """What a checkpoint needs of the write-ahead log (``wal.WriteAheadLog``)."""

    def rotate(self) -> int: ...

    def segments_done(self, wal_from: int) -> None: ...


def write_checkpoint(core: "ReplayCore", directory: str | Path, wal: CutLog | None = None) -> dict:
    """Snapshot ``core``'s online table into ``directory`` (atomically replaced), as of its cut.

    With ``wal``, a new log segment starts at the cut, and once the checkpoint is in place the
    segments before it are deleted."""
    directory = Path(directory)
    tmp = directory.with_name(directory.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    table = core.online
    started = time.monotonic()
    frames = isinstance(table, FrameRingTable)
    with core.lock:  # the cut: what the checkpoint holds, and where the log goes on
        meta = {"format": FORMAT, "obs_shape": list(core.schema.obs_shape), "obs_dtype": core.schema.obs_dtype,
                "n_actions": core.schema.n_actions, "capacity": table.capacity,
                # Items with keys in [tail, cut) are the checkpoint's; the counters below are theirs.
                "cut": table.inserted, "tail": table.tail, "frame_cut": table.store.inserted if frames else None,
                "actors": {k: dict(v) for k, v in core.actors.items()}, "actor_index": dict(core.actor_index),
                "evicted": core.evicted_stats(),
                "evicted_total": dict(core.evicted_total),
                # Seqs counted lost that a worker may still send (and, sent, are no longer lost).
                "gaps": {k: g.to_json() for k, g in core.gaps.items()},
                "mode": core.mode, "layout": "frames" if frames else "stacks",
                # Which run wrote it: a server of another run (or another env) refuses to restore it.
                "identity": dict(core.identity),
                # The first log segment not in this checkpoint (None: written without a log).
                "wal_from": wal.rotate() if wal is not None else None}
    # Ordinary file writes, not a memmap: on a full disk a memmap copy dies with SIGBUS (measured:
    # the server crashed, restarted 4 times and lost 86 % of the run), a write() raises OSError,
    # which the caller reports and retries later while the previous checkpoint stays valid.
    names = _columns(table)
    files = {name: (tmp / f"{name}.npy").open("wb") for name in names}
    if frames:
        files.update({name: (tmp / f"{name}.npy").open("wb") for name in ("frames", "frame_key")})
    try:
        keys = _copy_chunked(core, {name: getattr(table, name) for name in names},
                             {name: files[name] for name in names})
        if frames:  # after the rows: see the module's docstring
            _copy_chunked(core, {"frames": table.store.frames, "frame_key": table.store.key},
                          {name: files[name] for name in ("frames", "frame_key")})
        with core.lock:  # phases only move forward: the newest (a log replays the change anyway)
            meta.update(phase=core.phase, time=time.time())
        for f in files.values():
            f.flush()
            os.fsync(f.fileno())
    finally:
        for f in files.values():
            f.close()
    meta["items"] = items = int(((keys >= meta["tail"]) & (keys < meta["cut"])).sum())  # dropped since excluded
    (tmp / "meta.json").write_text(json.dumps(meta))
    old = directory.with_name(directory.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if directory.exists():
        directory.rename(old)
    tmp.rename(directory)
    shutil.rmtree(old, ignore_errors=True)
    if wal is not None:
        wal.segments_done(meta["wal_from"])
    return {"items": items, "seconds": round(time.monotonic() - started, 3), "path": str(directory),
            "wal_from": meta["wal_from"]}


def read_meta(directory: str | Path) -> dict:
    """A checkpoint's meta.json (CheckpointError if unreadable)."""
    directory = Path(directory)
    try:
        return json.loads((directory / "meta.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"replay checkpoint {directory}: unreadable meta.json ({exc})") from None


def _restore_frames(store, frame_key: np.ndarray, frames: np.ndarray, below: int) -> None:
    """Put a checkpoint's frames (keys below ``below``: from before its cut) back at their keys
    (the newest ones if the ring is now smaller)."""
    slots = np.flatnonzero((frame_key >= 0) & (frame_key < below))
    slots = slots[np.argsort(frame_key[slots], kind="stable")][-store.capacity:]
    if not slots.size:
        return
    fkeys = frame_key[slots]
    store.frames[fkeys % store.capacity] = np.asarray(frames[slots])
    store.key[fkeys % store.capacity] = fkeys
    store.inserted = int(fkeys.max()) + 1


def restore_checkpoint(core: "ReplayCore", directory: str | Path) -> int:
    """Put a checkpoint's items back into a fresh core (in key order), with every actor's counters
    as of the cut. Returns items restored. (The log's segments from ``wal_from`` on go after it:
    ``wal.replay``.)"""
    directory = Path(directory)
    meta = read_meta(directory)
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"replay checkpoint {directory}: format {meta.get('format')} != {FORMAT}"
                              + (" (written before the cut and the write-ahead log)" if meta.get("format") == 2 else ""))
    if (tuple(meta["obs_shape"]) != core.schema.obs_shape or meta["obs_dtype"] != core.schema.obs_dtype
            or meta["n_actions"] != core.schema.n_actions):
        raise CheckpointError(f"replay checkpoint {directory}: observation {meta['obs_shape']} {meta['obs_dtype']} / "
                              f"{meta['n_actions']} actions does not match the run's env")
    theirs, ours = meta.get("identity") or {}, core.identity
    for key in ("run_id", "config_digest"):
        if key in ours and theirs.get(key) != ours[key]:
            raise CheckpointError(f"replay checkpoint {directory}: written by a run with {key} {theirs.get(key)!r}, "
                                  f"this run has {ours[key]!r}")
    table = core.online
    frames = isinstance(table, FrameRingTable)
    if meta.get("layout", "stacks") != ("frames" if frames else "stacks"):
        raise CheckpointError(f"replay checkpoint {directory}: layout {meta.get('layout', 'stacks')} does not match "
                              f"the run's table")
    names = _columns(table)
    try:
        cols = {name: np.load(directory / f"{name}.npy", mmap_mode="r")
                for name in names + (("frames", "frame_key") if frames else ())}
    except (OSError, ValueError) as exc:
        raise CheckpointError(f"replay checkpoint {directory}: {exc}") from None
    keys = np.asarray(cols["key"])
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    # The cut's items: stored before it and not evicted by then (a row the copy found holding a
    # newer item: that one is in the log, or counted lost; the older one the log's replay evicts).
    order = order[(ordered >= int(meta["tail"])) & (ordered < int(meta["cut"]))]
    if frames:  # the frames first; then only items whose frames all came back
        _restore_frames(table.store, np.asarray(cols["frame_key"]), cols["frames"], int(meta["frame_cut"]))
        held = table.store.holds(np.asarray(cols["obs_key"])[order]).all(axis=1) & \
            table.store.holds(np.asarray(cols["next_key"])[order]).all(axis=1)
        order = order[held]
    if order.size and np.asarray(cols["steps"])[order].min() < 1:  # the wire refuses such items; so does this
        raise CheckpointError(f"replay checkpoint {directory}: an item with steps < 1")
    order = order[-table.capacity:]  # a smaller table keeps the newest items
    index = {k: int(v) for k, v in meta.get("actor_index", {}).items()}
    with core.lock:
        # The items go back oldest first into rows 0..n-1 with keys renumbered 0..n-1: no holes and
        # no collisions whatever the old capacity was (keys only identify items for priority updates).
        n = len(order)
        for name in names[:-1]:
            getattr(table, name)[:n] = np.asarray(cols[name][order])
        table.key[:n] = np.arange(n)
        table.inserted = n
        if frames:
            table.restored(n)
        core.selector.stored(table, table.tail, np.arange(n, dtype=np.int64))  # prioritized: leaves for them
        # Every actor's counters as of the cut, so each resumes after its last batch before it: a
        # batch stored after the cut is replayed from the log, or is a seq gap (counted lost).
        core.restore_actors(meta.get("actors", {}), index, meta.get("evicted", {}), meta.get("evicted_total", {}),
                            meta.get("gaps", {}))
        if core.cfg.pretrains and meta.get("mode") == core.mode:
            core.phase = max(core.phase, int(meta.get("phase", core.phase)))
    core.count_restored_as_sampled()
    return n
