"""The replay server's write-ahead log: every batch the server receives is written to disk before
it goes into the table, so a kill -9 of the server loses only what had not reached it yet.

What it protects against: the death of the replay server's process (kill -9, an OOM kill, a
crash). The service's logger thread takes each batch off the zenoh channel as it arrives, writes
it here with one ``write()`` (``write_transitions``) and hands it to the ingest thread, which
applies it (``ReplayCore.ingest``, which validates it) and then says so (``applied``). Once
``write()`` has returned the bytes are in the kernel's page cache, which outlives the process:
batches waiting behind a slow ingest (a checkpoint's copy, a burst) are as safe as stored ones,
and the write never holds the core's lock (a stall in it never delays a sample). That is not
host loss (power, a kernel panic): ``replay.wal: fsync`` also fsyncs each record, for a cost
measured in docs/RELIABILITY.md. Host loss is otherwise the periodic checkpoint's job
(``replay.checkpoint_every_s``).

Layout of ``<run dir>/replay_checkpoint.wal/`` (beside the checkpoint, which each write replaces
whole): segments ``<generation>.wal``, generation numbers rising for the life of the run dir.
A segment is a sequence of records::

    u32 body length | u32 crc32 of (kind byte + body) | u8 kind | body      (little endian)

Kinds: 0 HEADER (JSON: format, generation, the run's identity), the first record of every
segment; 1 TRANSITIONS (u16 length + the actor named by the message's key, then the message's
wire bytes as received: replay validates them as the live ingest did, refusing what it refused,
uncounted); 2 PHASE (one byte: the phase the learner set, written as the core makes the change;
workers act only on the phase-2 network, published after the server's phase changed, so no batch
the change decides arrives before it). A record that a kill cut short (its length runs past the end of the
file: ``torn``) or whose crc does not match (``corrupt``) ends its segment: it and whatever
follows it in that segment are dropped, counted and cut off the file (so a later restart does
not count them again). The batches they held show up as seq gaps: counted as lost.

With checkpoints: a checkpoint starts a new segment (``rotate``) at the instant it fixes its cut
(the table's insert counter), under the core's lock. Every batch applied before the cut is in the
checkpoint; every batch applied after it was written to the new segment or, if it was already
written but not yet applied (``pending``), to an older one: ``rotate`` returns the generation of
the oldest pending record (the new one's if none), which the checkpoint records (``meta.json``
``wal_from``); once it is in place the segments before that are deleted (``segments_done``). A
restart restores the checkpoint, then replays the segments from ``wal_from`` on, oldest first,
through ``ReplayCore.ingest`` with ``replaying``: a batch whose seq the actor's counters already
hold (applied before the cut) is skipped, so nothing is stored or counted twice.

Bounded: the log holds what arrived since the last completed checkpoint; past ``max_bytes``
(``replay.wal_max_mb``) it asks for a checkpoint at once (``checkpoint_due``).

    >>> import tempfile
    >>> log = WriteAheadLog(Path(tempfile.mkdtemp()), "write", {"run_id": "r"}, 0, first_gen=1)
    >>> log.write_transitions("w0", b"abc")
    True
    >>> [kind for kind, _, _ in scan(log.path(1).read_bytes())[0]]
    [0, 1]

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import collections
import json
import mmap
import os
import struct
import sys
import threading
import time
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .checkpoint import CheckpointError

if TYPE_CHECKING:  # pragma: no cover
    from .core import ReplayCore

FORMAT = 1
HEADER, TRANSITIONS, PHASE = 0, 1, 2
KINDS = (HEADER, TRANSITIONS, PHASE)
MODES = ("off", "write", "fsync")
_HEAD = struct.Struct("<IIB")  # body length, crc32 of kind + body, kind
_ACTOR = struct.Struct("<H")  # TRANSITIONS: the actor name's length, before the name and the message
SUFFIX = ".wal"
COMPLAIN_EVERY_S = 30.0  # at most one line on stderr per this many seconds about failing writes


class WalError(CheckpointError):
    """A log that must not be replayed into this server (another run's); the server refuses to start."""


def directory_for(checkpoint_dir: Path) -> Path:
    """The log of the checkpoint in ``checkpoint_dir``: beside it, ``<name>.wal``."""
    return checkpoint_dir.with_name(checkpoint_dir.name + SUFFIX)


def segments(directory: Path) -> list[tuple[int, Path]]:
    """The segments in ``directory``, oldest generation first."""
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    out = []
    for name in names:
        stem, _, ext = name.partition(".")
        if "." + ext == SUFFIX and stem.isdigit():
            out.append((int(stem), Path(directory) / name))
    return sorted(out)


def head(kind: int, *parts: bytes | bytearray | memoryview) -> bytes:
    """A record's 9 bytes before its body (``parts``, one after the other)."""
    crc = zlib.crc32(bytes((kind,)))
    for part in parts:
        crc = zlib.crc32(part, crc)
    return _HEAD.pack(sum(len(p) for p in parts), crc, kind)


def transitions_body(body: memoryview) -> tuple[str, memoryview]:
    """A TRANSITIONS record's (actor, message)."""
    (n,) = _ACTOR.unpack_from(body)
    return bytes(body[_ACTOR.size:_ACTOR.size + n]).decode(), body[_ACTOR.size + n:]


def scan(buf: bytes | bytearray | memoryview | mmap.mmap) -> tuple[list[tuple[int, int, int]], int, str | None]:
    """The whole records of a segment: ``([(kind, body start, body end)], where they end, why the
    scan stopped before the end)``: None (it did not), ``"torn"`` (a record runs past the end: a
    write cut short) or ``"corrupt"`` (a crc that does not match, an unknown kind)."""
    view = memoryview(buf)
    size, offset, out = len(view), 0, []
    try:
        while offset < size:
            if size - offset < _HEAD.size:
                return out, offset, "torn"
            length, crc, kind = _HEAD.unpack_from(view, offset)
            start, end = offset + _HEAD.size, offset + _HEAD.size + length
            if end > size:
                return out, offset, "torn"
            if kind not in KINDS or zlib.crc32(view[start:end], zlib.crc32(bytes((kind,)))) != crc:
                return out, offset, "corrupt"
            out.append((kind, start, end))
            offset = end
        return out, offset, None
    finally:
        view.release()


def _write_all(fd: int, parts: tuple[bytes | bytearray | memoryview, ...]) -> int:
    total = sum(len(p) for p in parts)
    done = os.writev(fd, parts)
    if done < total:  # a short write (rare on a regular file): the rest, from where it stopped
        rest = memoryview(b"".join(bytes(p) for p in parts))[done:]
        while rest:
            rest = rest[os.write(fd, rest):]
    return total


class WriteAheadLog:
    """The log a running server appends to (``mode`` write or fsync), or, with ``mode`` off, only
    the generation counter the checkpoints cut at and the deletion of segments a checkpoint holds.

    ``write_transitions`` (the logger thread) and ``applied`` (the ingest thread, once the core has
    taken the batch) keep the records written but not yet applied (``pending``); ``rotate`` (a
    checkpoint's cut, under the core's lock) and ``write_phase`` (under the core's lock) order
    themselves against them through this object's own lock. A write that fails (a full disk, a
    read-only dir) is counted and reported, the batch is still applied (it is in memory, and in
    the next checkpoint), and the next write starts a fresh segment.
    """

    def __init__(self, directory: Path, mode: str, identity: dict[str, str], max_bytes: int, first_gen: int,
                 kept: dict[int, int] | None = None):
        if mode not in MODES:
            raise ValueError(f"write-ahead log mode {mode!r} (known: {', '.join(MODES)})")
        self.directory, self.mode = Path(directory), mode
        self.enabled, self.fsync = mode != "off", mode == "fsync"
        self.identity, self.max_bytes = dict(identity), int(max_bytes)
        self.gen = first_gen - 1  # rotate() opens first_gen
        self._fd: int | None = None
        self._fresh = True  # the current segment holds its header only
        self._closed = False
        self._pending: collections.deque[int] = collections.deque()  # generations of records written, not applied
        # Bytes of each segment a restart would replay (those from before this process included).
        self._sizes: dict[int, int] = dict(kept or {})
        self._lock = threading.Lock()  # the fd and pending: logger and ingest threads, checkpoints, phase changes
        self.checkpoint_due = threading.Event()  # set when the log outgrows max_bytes
        self.appended = self.appended_bytes = self.failures = 0
        self._complained = 0.0
        self.last_error = ""
        if self.enabled:
            self.directory.mkdir(parents=True, exist_ok=True)
        self.rotate()

    def path(self, gen: int) -> Path:
        return self.directory / f"{gen:012d}{SUFFIX}"

    # ------------------------------------------------------------------ writing

    def write_transitions(self, actor: str, payload: bytes | bytearray | memoryview) -> bool:
        """Log a received TRANSITIONS message (``actor``: the one its key names) before it is
        applied. True if it is on disk (then ``applied()`` must follow once the core has taken or
        refused it); False if not (log off, or the write failed: counted)."""
        if not self.enabled:
            return False
        name = actor.encode()
        prefix = _ACTOR.pack(len(name)) + name
        first = head(TRANSITIONS, prefix, payload)  # the crc, before the lock is taken
        with self._lock:
            if not self._append((first, prefix, payload)):
                return False
            self._pending.append(self.gen)
            return True

    def applied(self) -> None:
        """The oldest pending record has been applied (or refused) by the core."""
        with self._lock:
            if self._pending:
                self._pending.popleft()

    def write_phase(self, phase: int) -> bool:
        """Log a phase change (under the core's lock, as the core makes it)."""
        if not self.enabled:
            return False
        body = bytes((phase,))
        with self._lock:
            return self._append((head(PHASE, body), body))

    def rotate(self) -> int:
        """Start a new segment (call under the core's lock: a checkpoint's cut). Returns the first
        generation a restart must replay after the checkpoint: the oldest record written but not
        yet applied, else the new segment's."""
        with self._lock:
            if self._closed:
                return self.gen
            self._close_fd()
            self.gen += 1
            if self.enabled:
                self._open(self.gen)
            return self._pending[0] if self._pending else self.gen

    def segments_done(self, wal_from: int) -> None:
        """A checkpoint that holds everything before segment ``wal_from`` is in place: delete those
        segments (any left by an earlier process too)."""
        for gen, path in segments(self.directory):
            if gen < wal_from:
                try:
                    path.unlink()
                except FileNotFoundError:
                    pass
                except OSError as exc:  # an unwritable dir: they are deleted after a later checkpoint
                    self._complain(f"could not delete {path} ({exc})")
                    continue
                with self._lock:
                    self._sizes.pop(gen, None)
        with self._lock:
            for gen in [g for g in self._sizes if g < wal_from]:
                self._sizes.pop(gen)
            if not (self.max_bytes and self.bytes > self.max_bytes):
                self.checkpoint_due.clear()

    def close(self) -> None:
        """At a clean stop: the current segment closed, and deleted if it holds no record."""
        with self._lock:
            self._close_fd()
            self._closed = True

    @property
    def bytes(self) -> int:
        """Bytes a restart would replay now (every segment since the last completed checkpoint)."""
        return sum(self._sizes.values())

    def state(self) -> dict[str, Any]:
        """For stats: what the log holds and what it has written."""
        with self._lock:
            return {"mode": self.mode, "generation": self.gen, "segments": len(self._sizes), "bytes": self.bytes,
                    "max_bytes": self.max_bytes, "records_written": self.appended, "bytes_written": self.appended_bytes,
                    "pending": len(self._pending), "failures": self.failures,
                    **({"last_error": self.last_error} if self.last_error else {})}

    # ------------------------------------------------------------------ internals (under self._lock)

    def _append(self, parts: tuple[bytes | bytearray | memoryview, ...]) -> bool:
        """Write one record (its head first) at the end of the current segment (a new one if the
        last write failed); in fsync mode fsync it. False if that failed (counted)."""
        if self._closed or (self._fd is None and not self._open(self.gen + 1)):
            return False
        try:
            n = _write_all(self._fd, parts)
        except OSError as exc:
            self._failed(exc, drop_segment=False)
            return False
        self._sizes[self.gen] = self._sizes.get(self.gen, 0) + n
        self._fresh = False
        self.appended += 1
        self.appended_bytes += n
        if self.fsync:
            try:
                os.fsync(self._fd)
            except OSError as exc:  # the record may be in the page cache only: counted, a new segment next
                self._failed(exc, drop_segment=True)
        if self.max_bytes and not self.checkpoint_due.is_set() and self.bytes > self.max_bytes:
            self.checkpoint_due.set()
        return True

    def _open(self, gen: int) -> bool:
        """Create segment ``gen`` with its header; on failure count it and leave no fd (the next
        write tries a newer generation)."""
        self.gen = gen
        path = self.path(gen)
        header = json.dumps({"format": FORMAT, "generation": gen, "identity": self.identity,
                             "time": time.time()}).encode()
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            self._failed(exc, drop_segment=True)
            return False
        try:
            _write_all(fd, (head(HEADER, header), header))
        except OSError as exc:
            os.close(fd)
            try:
                path.unlink()
            except OSError:
                pass
            self._failed(exc, drop_segment=True)
            return False
        self._fd, self._fresh = fd, True
        self._sizes[gen] = _HEAD.size + len(header)
        return True

    def _close_fd(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            if self.fsync:
                os.fsync(fd)
        except OSError as exc:
            self._failed(exc, drop_segment=False)
        finally:
            os.close(fd)
        if self._fresh:  # a header and nothing else: nothing to replay
            try:
                self.path(self.gen).unlink()
                self._sizes.pop(self.gen, None)
            except OSError:
                pass

    def _failed(self, exc: OSError, drop_segment: bool) -> None:
        """A write failed. The segment keeps its whole records: a part-record written is cut off
        again; where even that fails (or ``drop_segment``) the fd is closed and the next write
        opens a new segment. Counted, and reported at most every COMPLAIN_EVERY_S."""
        self.failures += 1
        self.last_error = f"{type(exc).__name__}: {exc}"
        fd = self._fd
        if fd is not None and not drop_segment:
            try:
                os.ftruncate(fd, self._sizes.get(self.gen, 0))  # O_APPEND: the next write goes at the new end
            except OSError:
                drop_segment = True
        if fd is not None and drop_segment:
            self._fd = None
            try:
                os.close(fd)
            except OSError:
                pass
        self._complain(f"write-ahead log write failed ({exc}); the batch is applied and will be in the next "
                       f"checkpoint, but a kill before then loses it ({self.failures} failed so far)")

    def _complain(self, text: str) -> None:
        now = time.monotonic()
        if now - self._complained >= COMPLAIN_EVERY_S:
            self._complained = now
            print(f"replay-server: {text}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------- startup


def last_generation(directory: Path) -> int:
    """The newest segment's generation in ``directory`` (0 if none)."""
    found = segments(directory)
    return found[-1][0] if found else 0


def clear(directory: Path) -> int:
    """Delete every segment (a server that does not restore must not replay a stale log later).
    Returns how many."""
    found = segments(directory)
    for _, path in found:
        path.unlink(missing_ok=True)
    return len(found)


def replay(core: "ReplayCore", directory: Path, from_gen: int | None) -> dict[str, int]:
    """Apply the segments from ``from_gen`` on (all of them when None: no checkpoint, or one
    written without a log) to ``core``, oldest first; delete those before it (a checkpoint holds
    them: the process died before it deleted them). Returns what was done, for stats: segments
    read, batches and items stored again, ``duplicates`` (batches the core already held: skipped),
    ``refused`` (records the core did not take), ``torn`` / ``corrupt`` records (each ends its
    segment, and is cut off the file) and the bytes those dropped.

    Raises WalError if a segment was written for another run (``core.identity``).
    """
    done = {"segments": 0, "batches": 0, "items": 0, "phase_records": 0, "duplicates": 0, "refused": 0,
            "torn": 0, "corrupt": 0, "dropped_bytes": 0}
    inserted_before = core.online.inserted
    for gen, path in segments(directory):
        if from_gen is not None and gen < from_gen:
            path.unlink(missing_ok=True)
            continue
        done["segments"] += 1
        with path.open("rb") as f:
            size = os.fstat(f.fileno()).st_size
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
        try:
            records, end, problem = scan(buf)
            if records and records[0][0] == HEADER:
                _check_header(core, path, bytes(buf[records[0][1]:records[0][2]]))
            elif records:  # no header first: not a segment this code wrote
                records, end, problem = [], 0, "corrupt"
            view = memoryview(buf)
            try:
                for kind, start, stop in records[1:]:
                    if kind == TRANSITIONS:
                        actor, message = transitions_body(view[start:stop])
                        reason = core.ingest(message, actor, replaying=True)
                        key = "batches" if reason is None else "duplicates" if reason == "duplicate" else "refused"
                        done[key] += 1
                    elif kind == PHASE:
                        done["phase_records"] += 1
                        try:
                            core.set_phase(view[start])
                        except ValueError:
                            done["refused"] += 1
            finally:
                view.release()
        finally:
            if isinstance(buf, mmap.mmap):
                try:
                    buf.close()
                except BufferError:  # a view still held somewhere: the collector closes it
                    pass
        if problem:
            done[problem] += 1
            done["dropped_bytes"] += size - end
            if end == 0:
                path.unlink(missing_ok=True)
            else:
                os.truncate(path, end)  # reported once: the next restart reads whole records only
    done["items"] = core.online.inserted - inserted_before
    if done["items"]:
        core.count_restored_as_sampled()
    return done


def _check_header(core: "ReplayCore", path: Path, raw: bytes) -> None:
    try:
        header = json.loads(raw)
    except ValueError:
        raise WalError(f"replay write-ahead log {path}: unreadable header") from None
    if header.get("format") != FORMAT:
        raise WalError(f"replay write-ahead log {path}: format {header.get('format')} != {FORMAT}")
    theirs, ours = header.get("identity") or {}, core.identity
    for key in ("run_id", "config_digest"):
        if key in ours and theirs.get(key) != ours[key]:
            raise WalError(f"replay write-ahead log {path}: written by a run with {key} {theirs.get(key)!r}, "
                           f"this run has {ours[key]!r}")
