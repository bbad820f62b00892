"""Checkpoints of the online table that never stop inserts or samples for long.

A checkpoint copies the ring in chunks; each chunk is copied under the core's lock (about a
millisecond), and the lock is released between chunks, so actors and the learner keep going
while it runs. Every row carries its item's key (insertion counter), so the snapshot is a set of
complete items even when inserts overwrite rows mid-checkpoint: a row copied after being
overwritten simply holds the newer item. The files go to a temp directory that is renamed over
the previous checkpoint at the end, so a crash (even kill -9) leaves either the old or the new
checkpoint, never a torn one. After a kill -9, what is lost is at most what arrived since the
last checkpoint started (``replay.checkpoint_every_s`` plus the copy time).

The demo table is not checkpointed: it is reloaded from its shard, whose sha256 is verified.

A table of stacked frames (``frames.FrameRingTable``) has ``obs_key`` / ``next_key`` in place of
``obs`` / ``next_obs``, and its frame ring in ``frames.npy`` + ``frame_key.npy``, copied after the
rows. Frames overwritten between the two copies belong to the oldest items (the ring is FIFO);
restore drops those items as the ring would have, and keeps every item whose frames are all there.

Layout of ``<run dir>/replay_checkpoint/``: one ``.npy`` per column (``obs``, ``next_obs``,
``action``, ``reward``, ``terminated``, ``truncated``, ``steps``, ``actor``, ``version``, ``key``) and
``meta.json`` (format version, schema, counters, per-actor stats).

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .frames import FrameRingTable

if TYPE_CHECKING:  # pragma: no cover
    from .core import ReplayCore

FORMAT = 2  # 2: the steps column (n-step returns)
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


def write_checkpoint(core: "ReplayCore", directory: str | Path) -> dict:
    """Snapshot ``core``'s online table into ``directory`` (atomically replaced)."""
    directory = Path(directory)
    tmp = directory.with_name(directory.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    table = core.online
    started = time.monotonic()
    # Ordinary file writes, not a memmap: on a full disk a memmap copy dies with SIGBUS (measured:
    # the server crashed, restarted 4 times and lost 86 % of the run), a write() raises OSError,
    # which the caller reports and retries later while the previous checkpoint stays valid.
    names = _columns(table)
    files = {name: (tmp / f"{name}.npy").open("wb") for name in names}
    frames = isinstance(table, FrameRingTable)
    if frames:
        files.update({name: (tmp / f"{name}.npy").open("wb") for name in ("frames", "frame_key")})
    try:
        keys = _copy_chunked(core, {name: getattr(table, name) for name in names},
                             {name: files[name] for name in names})
        if frames:  # after the rows: see the module's docstring
            _copy_chunked(core, {"frames": table.store.frames, "frame_key": table.store.key},
                          {name: files[name] for name in ("frames", "frame_key")})
        with core.lock:
            meta = {"format": FORMAT, "obs_shape": list(core.schema.obs_shape), "obs_dtype": core.schema.obs_dtype,
                    "n_actions": core.schema.n_actions, "capacity": table.capacity, "inserted": table.inserted,
                    "actors": {k: dict(v) for k, v in core.actors.items()}, "actor_index": dict(core.actor_index),
                    # Read together with "actors", after the copy: restore uses it to drop a batch
                    # the copy caught in part and to find each actor's env steps at its last whole batch.
                    "batch_history": {k: [list(b) for b in h] for k, h in core.batch_history.items()},
                    "evicted": core.evicted_stats(),
                    "evicted_total": dict(core.evicted_total),
                    "phase": core.phase, "mode": core.mode, "time": time.time(), "tail": table.tail,
                    "layout": "frames" if frames else "stacks",
                    # Which run wrote it: a server of another run (or another env) refuses to restore it.
                    "identity": dict(core.identity)}
        for f in files.values():
            f.flush()
            os.fsync(f.fileno())
    finally:
        for f in files.values():
            f.close()
    meta["items"] = items = int((keys >= max(0, meta["tail"])).sum())  # rows dropped since (frames) excluded
    (tmp / "meta.json").write_text(json.dumps(meta))
    old = directory.with_name(directory.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if directory.exists():
        directory.rename(old)
    tmp.rename(directory)
    shutil.rmtree(old, ignore_errors=True)
    return {"items": items, "seconds": round(time.monotonic() - started, 3), "path": str(directory)}


def _restore_frames(store, frame_key: np.ndarray, frames: np.ndarray) -> None:
    """Put a checkpoint's frames back at their keys (the newest ones if the ring is now smaller)."""
    slots = np.flatnonzero(frame_key >= 0)
    slots = slots[np.argsort(frame_key[slots], kind="stable")][-store.capacity:]
    if not slots.size:
        return
    fkeys = frame_key[slots]
    store.frames[fkeys % store.capacity] = np.asarray(frames[slots])
    store.key[fkeys % store.capacity] = fkeys
    store.inserted = int(fkeys.max()) + 1


def _whole_batches(order: np.ndarray, actor: np.ndarray, seq: np.ndarray, index: dict[str, int],
                   history: dict[str, dict[int, tuple[int, int]]]) -> tuple[np.ndarray, dict[str, tuple[int, int | None]]]:
    """Drop each actor's newest batch if the chunked copy caught it only in part, and say where each
    actor resumes: (seq of its newest whole batch, its env steps then; None if not in the history).

    ``order`` holds the rows to restore. The copy sweeps the ring once, so of each actor's batches it
    holds all up to some point (older ones the ring overwrote aside) plus at most one in part.
    """
    keep = np.ones(order.size, bool)
    resume: dict[str, tuple[int, int | None]] = {}
    for name, i in index.items():
        mine = np.flatnonzero(actor[order] == i)
        if not mine.size:
            continue
        seqs = seq[order][mine]
        newest = int(seqs.max())
        known = history.get(name, {})
        if newest not in known:
            resume[name] = (newest, None)
        elif int((seqs == newest).sum()) < known[newest][1]:
            keep[mine[seqs == newest]] = False  # a part of a batch: its items count as lost, none kept
            resume[name] = (newest - 1, known[newest][0] - known[newest][1])
        else:
            resume[name] = (newest, known[newest][0])
    return order[keep], resume


def restore_checkpoint(core: "ReplayCore", directory: str | Path) -> int:
    """Put a checkpoint's items back into a fresh core (in key order). Returns items restored."""
    directory = Path(directory)
    try:
        meta = json.loads((directory / "meta.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"replay checkpoint {directory}: unreadable meta.json ({exc})") from None
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"replay checkpoint {directory}: format {meta.get('format')} != {FORMAT}")
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
    order = order[keys[order] >= int(meta.get("tail", 0))]
    if frames:  # the frames first; then only items whose frames all came back
        _restore_frames(table.store, np.asarray(cols["frame_key"]), cols["frames"])
        held = table.store.holds(np.asarray(cols["obs_key"])[order]).all(axis=1) & \
            table.store.holds(np.asarray(cols["next_key"])[order]).all(axis=1)
        order = order[held]
    if order.size and np.asarray(cols["steps"])[order].min() < 1:  # the wire refuses such items; so does this
        raise CheckpointError(f"replay checkpoint {directory}: an item with steps < 1")
    index = {k: int(v) for k, v in meta.get("actor_index", {}).items()}
    history = {k: {int(seq): (int(steps), int(n)) for seq, steps, n in h}
               for k, h in meta.get("batch_history", {}).items()}
    order, resume = _whole_batches(order, np.asarray(cols["actor"]), np.asarray(cols["seq"]), index, history)
    order = order[-table.capacity:]  # a smaller table keeps the newest items
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
        core.restore_actors(meta.get("actors", {}), index, meta.get("batch_history", {}), meta.get("evicted", {}),
                            meta.get("evicted_total", {}))
        # Each actor resumes after the newest batch whose items are all here (the stats in
        # meta.json were read after the chunked copy and may name batches it missed), with the env
        # steps it had made by then: every batch missing after a restart shows up as a seq gap and
        # its items as lost, and a restarted worker makes exactly the missing steps again.
        for name, (last_seq, env_steps) in resume.items():
            if name in core.actors:
                stats = core.actors[name]
                # Its counters as of that batch: the batches after it (in the stats, not in the
                # table) are sent again by a resumed worker or counted lost, never stored twice.
                after = [(seq, n) for seq, (_, n) in history.get(name, {}).items() if seq > last_seq]
                for key in ("batches", "items", "stored"):
                    stats[key] = max(0, int(stats.get(key, 0)) - (len(after) if key == "batches" else
                                                                  sum(n for _, n in after)))
                stats["last_seq"] = last_seq
                if env_steps is not None:
                    stats["env_steps"] = env_steps
        if core.cfg.pretrains and meta.get("mode") == core.mode:
            core.phase = max(core.phase, int(meta.get("phase", core.phase)))
        # The restored items count as already sampled at the configured ratio: counting them as
        # fresh inserts with no samples froze the actors for 10-33 s after a restart, waiting for
        # the learner to "catch up" on data it had long learned from.
        core.samples = int(max(0, n - core.cfg.min_size) * core.cfg.samples_per_insert)
    return n
