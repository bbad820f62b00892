"""The replay server's write-ahead log (replay_server/wal.py): every accepted batch is replayed
after a restart, a torn or corrupt record is dropped once and counted, a replay never stores or
counts a batch twice, and a checkpoint cuts the log back.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ConfigError, ReplayConfig, load_run_config
from laneshift.replay_server import wal as W
from laneshift.replay_server.checkpoint import read_meta, restore_checkpoint, write_checkpoint
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.storage import DemoTable

SCHEMA = wire.TransitionSchema((6,), "float32", 31)
IDENTITY = {"run_id": "run", "config_digest": "abc"}


def batch(seq: int, n: int = 10, actor: str = "w0", phase: int = 0) -> bytes:
    """Item k of an actor's stream carries k in every field (see test_replay_checkpoint)."""
    k = np.arange(seq * n, seq * n + n)
    obs = np.repeat(k[:, None], 6, axis=1).astype(np.float32)
    return wire.encode_transitions(wire.TransitionBatch.from_arrays(
        actor=actor, seq=seq, weights_version=seq, phase=phase, env_steps=(seq + 1) * n, obs=obs, action=k % 31,
        reward=k.astype(np.float32), next_obs=obs + 1, terminated=k % 2, truncated=np.zeros(n)))


def new_core(capacity: int = 1000, **kw) -> ReplayCore:
    core = ReplayCore(ReplayConfig(capacity=capacity, min_size=1, **kw), SCHEMA)
    core.identity = dict(IDENTITY)
    return core


def receive(core: ReplayCore, payload: bytes, actor: str | None = None) -> str | None:
    """What the service does with a received batch: log it, apply it, tell the log."""
    if actor is None:
        actor = wire.decode_transitions(payload, SCHEMA).actor
    logged = core.wal.write_transitions(actor, payload)
    try:
        return core.ingest(payload, actor)
    finally:
        if logged:
            core.wal.applied()


def logged_core(directory: Path, mode: str = "write", capacity: int = 1000, max_bytes: int = 0,
                **kw) -> ReplayCore:
    core = new_core(capacity, **kw)
    core.wal = W.WriteAheadLog(directory, mode, core.identity, max_bytes, first_gen=1)
    return core


def restart(directory: Path, checkpoint: Path | None = None, capacity: int = 1000, **kw) -> tuple[ReplayCore, dict]:
    """What a restarted server does: the checkpoint (if any), then the log after it."""
    core = new_core(capacity, **kw)
    wal_from = None
    if checkpoint is not None and (checkpoint / "meta.json").exists():
        restore_checkpoint(core, checkpoint)
        wal_from = read_meta(checkpoint)["wal_from"]
    return core, W.replay(core, directory, wal_from)


def items(core: ReplayCore) -> list[int]:
    t = core.online
    return sorted(int(x) for x in t.reward[:t.size])


def test_every_batch_is_replayed_and_one_refused_is_refused_again_uncounted(tmp_path):
    core = logged_core(tmp_path / "wal")
    for seq in range(5):
        assert receive(core, batch(seq)) is None
    assert receive(core, b"garbage", "w0") == "truncated"  # logged as received, refused when applied
    assert receive(core, batch(5, actor="w1"), "w0") == "actor_mismatch"  # the key's actor is logged too
    assert core.rejected == {"truncated": 1, "actor_mismatch": 1}
    fresh, done = restart(tmp_path / "wal")
    assert (done["batches"], done["refused"], done["items"]) == (5, 2, 50)
    assert done["torn"] == done["corrupt"] == 0
    assert items(fresh) == list(range(50))
    assert fresh.actors == core.actors
    assert fresh.rejected == {}  # counted when they arrived, not again
    assert fresh.actor_state("w0") == {"env_steps": 50, "next_seq": 5, "known": 1}


@pytest.mark.parametrize("cut", [1, 5, 9, 9 + 20, -1])
def test_a_torn_tail_is_dropped_once_counted_and_its_batch_counted_lost(tmp_path, cut):
    """kill -9 in the middle of a write: the last record is cut short (inside its head, or its
    body). The whole records before it come back, the torn one is counted, cut off the file (a
    second restart does not count it again), and its batch is a seq gap: counted as lost."""
    core = logged_core(tmp_path / "wal")
    for seq in range(4):
        receive(core, batch(seq))
    (gen, path), = W.segments(tmp_path / "wal")
    whole = path.stat().st_size
    records, _, _ = W.scan(path.read_bytes())
    last = whole - (records[-1][1] - len(W.head(W.TRANSITIONS, b"")))  # the last record, head and body
    os.truncate(path, whole - last + cut if cut > 0 else whole + cut)
    fresh, done = restart(tmp_path / "wal")
    assert (done["batches"], done["torn"], done["corrupt"]) == (3, 1, 0)
    assert done["dropped_bytes"] == (cut if cut > 0 else last + cut)
    assert path.stat().st_size == whole - last  # the torn part is gone from the file
    again, done2 = restart(tmp_path / "wal")
    assert (done2["batches"], done2["torn"]) == (3, 0)
    assert items(again) == items(fresh) == list(range(30))
    # The worker, not restarted, goes on with batch 4: batch 3 is counted lost, nothing is hidden.
    assert fresh.ingest(batch(4)) is None
    w0 = fresh.actors["w0"]
    assert (w0["stored"], w0["lost_batches"], w0["lost_items"]) == (40, 1, 10)
    assert w0["stored"] + w0["lost_items"] == w0["env_steps"] == 50


def test_a_corrupt_record_ends_its_segment_and_the_later_segments_still_count(tmp_path):
    core = logged_core(tmp_path / "wal")
    for seq in range(3):
        receive(core, batch(seq))
    core.wal.rotate()  # a second segment (as a checkpoint's cut would start, had it completed)
    for seq in range(3, 5):
        receive(core, batch(seq))
    (_, first), (_, second) = W.segments(tmp_path / "wal")
    data = bytearray(first.read_bytes())
    data[-100] ^= 0xFF  # a flipped byte in the last record of the first segment
    first.write_bytes(bytes(data))
    fresh, done = restart(tmp_path / "wal")
    assert (done["segments"], done["batches"], done["corrupt"], done["torn"]) == (2, 4, 1, 0)
    assert items(fresh) == list(range(20)) + list(range(30, 50))
    w0 = fresh.actors["w0"]
    assert (w0["lost_batches"], w0["lost_items"]) == (1, 10)  # batch 2: counted at the gap
    assert w0["stored"] + w0["lost_items"] == w0["env_steps"] == 50


def test_replay_is_idempotent_a_batch_the_core_holds_is_skipped(tmp_path):
    core = logged_core(tmp_path / "wal")
    for seq in range(4):
        receive(core, batch(seq))
    fresh, done = restart(tmp_path / "wal")
    before = {k: dict(v) for k, v in fresh.actors.items()}
    again = W.replay(fresh, tmp_path / "wal", None)  # the same segments once more
    assert (again["batches"], again["duplicates"], again["items"]) == (0, 4, 0)
    assert fresh.actors == before and items(fresh) == list(range(40))
    assert fresh.rejected == {} and fresh.online.inserted == 40


def test_a_batch_logged_before_the_cut_and_applied_after_it_is_replayed(tmp_path):
    """The ingest thread may be behind the logger: at the cut a batch can be on disk in the old
    segment, not yet applied. The checkpoint then starts its replay at that segment; the batches
    there that it holds are skipped by their seq."""
    core = logged_core(tmp_path / "wal")
    receive(core, batch(0))
    assert core.wal.write_transitions("w0", batch(1))  # logged, waiting for the ingest thread
    first = core.wal.gen
    info = write_checkpoint(core, tmp_path / "ckpt", core.wal)
    assert info["wal_from"] == first < core.wal.gen  # the old segment is kept
    assert core.ingest(batch(1), "w0") is None  # now applied: after the cut
    core.wal.applied()
    receive(core, batch(2))
    fresh, done = restart(tmp_path / "wal", tmp_path / "ckpt")
    assert (done["segments"], done["batches"], done["duplicates"]) == (2, 2, 1)
    assert items(fresh) == list(range(30)) and fresh.actors == core.actors
    write_checkpoint(core, tmp_path / "ckpt", core.wal)  # nothing pending: the old segments go
    assert [g for g, _ in W.segments(tmp_path / "wal")] == [core.wal.gen]


def test_a_checkpoint_cuts_the_log_and_restart_replays_only_after_the_cut(tmp_path):
    core = logged_core(tmp_path / "wal")
    for seq in range(5):
        receive(core, batch(seq))
    info = write_checkpoint(core, tmp_path / "ckpt", core.wal)
    assert [g for g, _ in W.segments(tmp_path / "wal")] == [info["wal_from"]]  # the older one deleted
    for seq in range(5, 8):
        receive(core, batch(seq))
    fresh, done = restart(tmp_path / "wal", tmp_path / "ckpt")
    assert (done["segments"], done["batches"], done["items"]) == (1, 3, 30)
    assert items(fresh) == list(range(80)) and fresh.actors == core.actors


def test_segments_a_completed_checkpoint_holds_are_not_replayed(tmp_path):
    """Killed after the checkpoint's rename, before it deleted the segments it holds: a restart
    deletes them instead of replaying them on top of the checkpoint."""
    core = logged_core(tmp_path / "wal")
    for seq in range(5):
        receive(core, batch(seq))
    kept = {p.name: p.read_bytes() for _, p in W.segments(tmp_path / "wal")}
    write_checkpoint(core, tmp_path / "ckpt", core.wal)
    for name, data in kept.items():
        (tmp_path / "wal" / name).write_bytes(data)  # as if the deletion never happened
    receive(core, batch(5))
    fresh, done = restart(tmp_path / "wal", tmp_path / "ckpt")
    assert (done["segments"], done["batches"], done["duplicates"]) == (1, 1, 0)
    assert items(fresh) == list(range(60)) and fresh.actors == core.actors
    assert not any((tmp_path / "wal" / name).exists() for name in kept)


def test_the_phase_change_is_replayed_between_the_batches_around_it(tmp_path):
    n = 50
    obs = np.zeros((n, 6), np.float32)
    demo = DemoTable(obs, np.zeros(n, np.int64), np.zeros(n, np.float32), obs, np.zeros(n, np.uint8), "d", {})
    core = ReplayCore(ReplayConfig(capacity=100, min_size=1, demo_mode="rehearsal"), SCHEMA, demo)
    core.wal = W.WriteAheadLog(tmp_path / "wal", "write", {}, 0, first_gen=1)
    receive(core, batch(0))  # phase 1: counted, not stored
    core.set_phase(2)
    receive(core, batch(1))
    fresh = ReplayCore(ReplayConfig(capacity=100, min_size=1, demo_mode="rehearsal"), SCHEMA, demo)
    done = W.replay(fresh, tmp_path / "wal", None)
    assert done["phase_records"] == 1 and fresh.phase == 2
    assert items(fresh) == items(core) == list(range(10, 20))
    assert fresh.dropped == core.dropped and fresh.actors == core.actors


def test_a_log_of_another_run_is_refused(tmp_path):
    core = logged_core(tmp_path / "wal")
    receive(core, batch(0))
    other = new_core()
    other.identity = {**IDENTITY, "run_id": "other"}
    with pytest.raises(W.WalError, match="run_id 'run', this run has 'other'"):
        W.replay(other, tmp_path / "wal", None)


def test_a_failed_write_is_counted_the_batch_still_applied_and_the_log_goes_on(tmp_path, monkeypatch):
    core = logged_core(tmp_path / "wal")
    receive(core, batch(0))
    real = os.writev
    calls = {"n": 0}

    def full_disk(fd, parts):
        calls["n"] += 1
        if calls["n"] == 1:
            os.write(fd, bytes(parts[0])[:5])  # a part of the head reached the file before the error
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, parts)

    monkeypatch.setattr(W.os, "writev", full_disk)
    assert receive(core, batch(1)) is None  # applied in memory all the same
    assert core.stats()["wal"]["failures"] == 1
    receive(core, batch(2))
    assert items(core) == list(range(30))
    fresh, done = restart(tmp_path / "wal")
    assert done["torn"] == done["corrupt"] == 0  # the part-record was cut off again at once
    assert items(fresh) == list(range(10)) + list(range(20, 30))
    w0 = fresh.actors["w0"]
    assert (w0["lost_batches"], w0["lost_items"]) == (1, 10)  # batch 1: not in the log, counted
    assert w0["stored"] + w0["lost_items"] == w0["env_steps"]


def test_the_log_asks_for_a_checkpoint_past_its_bound_and_is_cut_back(tmp_path):
    core = logged_core(tmp_path / "wal", max_bytes=3 * len(batch(0)))
    for seq in range(2):
        receive(core, batch(seq))
    assert not core.wal.checkpoint_due.is_set()
    for seq in range(2, 4):
        receive(core, batch(seq))
    assert core.wal.checkpoint_due.is_set()
    info = write_checkpoint(core, tmp_path / "ckpt", core.wal)
    assert not core.wal.checkpoint_due.is_set() and core.wal.bytes < len(batch(0))  # the new segment's header
    assert [g for g, _ in W.segments(tmp_path / "wal")] == [info["wal_from"]]


def test_a_clean_close_leaves_no_empty_segment_and_off_writes_nothing(tmp_path):
    core = logged_core(tmp_path / "wal")
    receive(core, batch(0))
    write_checkpoint(core, tmp_path / "ckpt", core.wal)  # the final checkpoint: a new, empty segment
    core.wal.close()
    assert W.segments(tmp_path / "wal") == []
    off = logged_core(tmp_path / "off", mode="off")
    receive(off, batch(0))
    assert not (tmp_path / "off").exists() and off.stats()["wal"]["mode"] == "off"
    info = write_checkpoint(off, tmp_path / "ckpt2", off.wal)
    assert info["wal_from"] == 2  # generations still count, so a later log's segments sort after the cut


def test_fsync_mode_syncs_every_record(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(W.os, "fsync", lambda fd: (synced.append(fd), real(fd)))
    core = logged_core(tmp_path / "wal", mode="fsync")
    for seq in range(3):
        receive(core, batch(seq))
    assert len(synced) == 3
    fresh, done = restart(tmp_path / "wal")
    assert done["batches"] == 3


def test_the_config_fields():
    cfg = load_run_config(overrides={"replay.wal": "fsync", "replay.wal_max_mb": 64})
    assert (cfg.replay.wal, cfg.replay.wal_max_mb) == ("fsync", 64.0)
    assert load_run_config(overrides={"replay.wal": False}).replay.wal == "off"  # YAML's bare `off`
    with pytest.raises(ConfigError, match=r"^replay\.wal: must be off, write or fsync"):
        load_run_config(overrides={"replay.wal": "sometimes"})
    with pytest.raises(ConfigError, match=r"^replay\.wal_max_mb"):
        load_run_config(overrides={"replay.wal_max_mb": -1})


def test_overwrite_removes_every_replay_log_of_the_previous_run(tmp_path):
    """A stale log of the run before would be replayed into the new one (same run id, same config)."""
    import io

    from laneshift.deploy.run_dir import prepare_run_dir

    (tmp_path / "config.yaml").write_text("{}\n")
    for name in ("replay_checkpoint.wal", "replay_checkpoint_shard1.wal", "replay_checkpoint_shard1"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "000000000001.wal").write_bytes(b"x")
    (tmp_path / "replay_stats_shard1.json").write_text("{}")
    prepare_run_dir(tmp_path, resume=False, overwrite=True, out=io.StringIO())
    assert sorted(p.name for p in tmp_path.iterdir()) == []
