"""``replay_server.core.ReplayCore`` and ``replay_server.rate_limiter`` in-process (no zenoh).

Online transitions are built so that ``obs[:, 0]`` equals the item's insertion key and demo
transitions have ``obs[:, 0] = -(row + 1)``: every sampled row can be traced to where it came from.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import hashlib
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.replay_server import actor_ledger
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.rate_limiter import SampleToInsertRatio
from laneshift.replay_server.storage import DemoTable, RingTable
from laneshift.wire import SampleRequest, TransitionBatch, TransitionSchema, WireError
from laneshift.wire.batches import BATCH_FIELDS

SCHEMA = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=5)
FUZZ = settings(derandomize=True, database=None, deadline=None, max_examples=150,
                suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- helpers


def demo_table(n: int) -> DemoTable:
    obs = np.zeros((n, 3), np.float32)
    obs[:, 0] = -(np.arange(n) + 1)
    obs[:, 1] = 0.5
    return DemoTable(obs=obs, action=(np.arange(n) % 5).astype(np.int64), reward=np.full(n, 0.25, np.float32),
                     next_obs=obs + 100, terminated=(np.arange(n) % 7 == 0).astype(np.uint8), sha256="d" * 64,
                     metadata={"episodes": 1})


def tmsg(actor: str = "w0", seq: int = 0, rows: int = 4, start: int = 0, version: int = 0, phase: int = 0,
         env_steps: int | None = None) -> bytes:
    """A valid transitions message whose obs[:, 0] are the keys start .. start + rows - 1."""
    obs = np.zeros((rows, 3), np.float32)
    obs[:, 0] = np.arange(start, start + rows)
    obs[:, 2] = 1.0
    return wire.encode_transitions(TransitionBatch.from_arrays(
        actor=actor, seq=seq, weights_version=version, phase=phase,
        env_steps=start + rows if env_steps is None else env_steps, obs=obs, action=np.arange(rows) % 5,
        reward=np.ones(rows, np.float32), next_obs=obs + 0.5, terminated=np.zeros(rows), truncated=np.zeros(rows)))


def make_core(mode: str = "none", demo: int = 0, **kw) -> ReplayCore:
    fields = {"capacity": 100, "min_size": 1, "samples_per_insert": 0.0, "demo_mode": mode}
    if mode != "none":
        fields["demo_paths"] = ("unused",)
    fields.update(kw)
    return ReplayCore(ReplayConfig(**fields), SCHEMA, demo_table(demo) if demo else None)


def fill(core: ReplayCore, total: int, batch: int = 50, actors: tuple[str, ...] = ("w0", "w1")) -> None:
    """Insert ``total`` items round-robin over ``actors``; obs[:, 0] is each item's insertion key."""
    for i, done in enumerate(range(0, total, batch)):
        actor = actors[i % len(actors)]
        seq = core.actors.get(actor, {}).get("last_seq", -1) + 1
        assert core.ingest(tmsg(actor, seq, min(batch, total - done), core.online.inserted), actor) is None


def sample_ok(core: ReplayCore, req: SampleRequest) -> wire.SampledBatch:
    out = core.sample(req)
    assert isinstance(out, wire.SampledBatch), out
    return out


def check_rows_traceable(core: ReplayCore, b: wire.SampledBatch) -> None:
    """Every sampled row is exactly the stored item it claims (is_demo + index)."""
    d = b.is_demo.astype(bool)
    assert np.array_equal(b.obs[d], core.demo.obs[b.index[d]])
    assert np.array_equal(b.action[d], core.demo.action[b.index[d]])
    assert np.array_equal(b.next_obs[d], core.demo.next_obs[b.index[d]])
    o = ~d
    assert core.online.valid(b.index[o]).all()
    assert np.array_equal(b.obs[o, 0], b.index[o].astype(np.float32))
    assert np.array_equal(b.next_obs[o], b.obs[o] + 0.5)
    assert (b.weight == 1).all() and b.weight.dtype == np.float32


def snapshot(table: RingTable) -> dict[str, np.ndarray]:
    names = ("obs", "next_obs", "action", "reward", "terminated", "truncated", "actor", "version")
    return {n: getattr(table, n).copy() for n in names}


# --------------------------------------------------------------------------- mode none


def test_none_mode_holds_demos_but_never_samples_them():
    core = make_core("none", demo=20)
    assert core.demo.size == 0 and core.demo_held.size == 20 and core.online.capacity == 100
    fill(core, 60)
    b = sample_ok(core, SampleRequest(32, 4))
    assert b.is_demo.sum() == 0 and b.num_batches == 4 and len(b.action) == 128
    check_rows_traceable(core, b)
    s = core.stats()
    assert s["demo_share_buffer"] == 0.0 and s["tables"]["demo"]["held"] == 20 and s["phase"] == 0


def test_sampling_waits_for_min_size():
    core = make_core("none", min_size=10)
    fill(core, 8, batch=4)
    out = core.sample(SampleRequest(4))
    assert isinstance(out, WireError) and out.reason == "rate_limited" and out.retry_after_ms == 5
    fill(core, 2, batch=2, actors=("w9",))
    sample_ok(core, SampleRequest(4))
    assert core.stats()["requests"] == {"rate_limited": 1, "served": 1}


def test_online_keys_after_wrap_are_the_newest_items():
    core = make_core("none", capacity=10)
    fill(core, 37, batch=3)
    assert core.online.inserted == 37 and core.online.size == 10
    assert np.array_equal(np.sort(core.online.obs[:, 0]), np.arange(27, 37, dtype=np.float32))
    b = sample_ok(core, SampleRequest(64, 4))
    assert set(b.index.tolist()) <= set(range(27, 37))
    check_rows_traceable(core, b)


def test_a_batch_larger_than_the_table_keeps_its_newest_rows():
    core = make_core("none", capacity=10)
    assert core.ingest(tmsg(rows=25), "w0") is None
    assert core.online.inserted == 25
    assert np.array_equal(np.sort(core.online.obs[:, 0]), np.arange(15, 25, dtype=np.float32))
    check_rows_traceable(core, sample_ok(core, SampleRequest(16)))


# --------------------------------------------------------------------------- retention


def test_retention_regions_and_demo_share():
    core = make_core("retention", demo=300, capacity=1000, demo_ratio=0.1, min_size=100, seed=3)
    # round(0.1 * 1000) demo items, fixed; the online FIFO gets the rest.
    assert core.demo.size == 100 and core.online.capacity == 900 and core.limiter.capacity == 900
    rows = (-core.demo.obs[:, 0] - 1).astype(int)
    assert len(set(rows)) == 100 and np.all(np.diff(rows) > 0) and rows.max() < 300  # seeded subset, sorted
    assert np.array_equal(core.demo.obs, core.demo_held.obs[rows])
    digest = core.demo.digest()
    held_digest = core.demo_held.digest()

    fill(core, 450)  # online half full: demo share of the buffer is 100 / 550
    assert core.stats()["demo_share_buffer"] == pytest.approx(100 / 550)
    fill(core, 6000)  # wraps the 900-item online table more than 6 times
    assert core.online.inserted == 6450 and core.online.size == 900
    stats = core.stats()
    assert stats["demo_share_buffer"] == 0.1
    assert stats["tables"]["demo"]["size"] == 100 and stats["tables"]["demo"]["held"] == 300

    demo_rows = total = 0
    for _ in range(100):
        b = sample_ok(core, SampleRequest(256, 2))
        check_rows_traceable(core, b)
        demo_rows += int(b.is_demo.sum())
        total += len(b.is_demo)
        assert b.info == {"phase": 0, "prioritized": False, "live": 1000}
    share = demo_rows / total  # 51,200 rows: standard error 0.0013
    assert abs(share - 0.1) < 0.01, share
    s = core.stats()
    assert s["sampled_rows"] == total and s["sampled_demo_rows"] == demo_rows
    assert abs(s["demo_share_recent_samples"] - 0.1) < 0.02
    # Not one demo byte changed, and the tables cannot be written.
    assert core.demo.digest() == digest and core.demo_held.digest() == held_digest
    with pytest.raises(ValueError):
        core.demo.obs[0, 0] = 1.0


def test_retention_demo_subset_is_seeded():
    a = make_core("retention", demo=300, capacity=1000, seed=1)
    b = make_core("retention", demo=300, capacity=1000, seed=1)
    c = make_core("retention", demo=300, capacity=1000, seed=2)
    assert a.demo.digest() == b.demo.digest() != c.demo.digest()


def test_retention_uses_whole_shard_when_it_is_exactly_the_region():
    core = make_core("retention", demo=100, capacity=1000, demo_ratio=0.1)
    assert core.demo.digest() == core.demo_held.digest()


def test_retention_refused_when_the_shard_is_too_small():
    with pytest.raises(ValueError, match=r"replay\.demo_ratio.*needs 100 demo transitions.*has 99"):
        make_core("retention", demo=99, capacity=1000, demo_ratio=0.1)
    with pytest.raises(ValueError, match="replay.demo_ratio"):
        make_core("retention", demo=0, capacity=1000, demo_ratio=0.1)


def test_retention_min_size_must_fit_the_online_region():
    with pytest.raises(ValueError, match="replay.min_size"):
        make_core("retention", demo=600, capacity=1000, demo_ratio=0.5, min_size=600)


# --------------------------------------------------------------------------- rehearsal


def test_rehearsal_phase1_demos_only_and_drops_agent_transitions():
    core = make_core("rehearsal", demo=64, min_size=20, samples_per_insert=2.0, spi_tolerance=64)
    assert core.phase == 1 and core.demo.size == 64
    b = sample_ok(core, SampleRequest(32, 2))  # no online data, no min_size in phase 1
    assert b.is_demo.all() and b.index.max() < 64 and b.info == {"phase": 1, "prioritized": False, "live": b.info["live"]}
    check_rows_traceable(core, b)
    assert core.samples == 0  # phase-1 samples do not count for the rate limiter
    assert core.insert_allowed()

    before = snapshot(core.online)
    assert core.ingest(tmsg("w0", 0, rows=10), "w0") is None
    assert core.ingest(tmsg("w1", 0, rows=7), "w1") is None
    assert core.online.inserted == 0
    assert all(np.array_equal(v, getattr(core.online, k)) for k, v in before.items())
    s = core.stats()
    assert s["dropped"] == {"rehearsal_phase1": 17} and s["rejected"] == {}
    assert s["actors"]["w0"]["items"] == 10 and s["actors"]["w0"]["stored"] == 0
    assert s["demo_share_buffer"] == 1.0


def test_rehearsal_phase2_is_online_only_and_phases_never_go_back():
    core = make_core("rehearsal", demo=64, min_size=20)
    digest = core.demo.digest()
    core.set_phase(1)  # staying in phase 1 is allowed
    core.set_phase(2)
    assert core.phase == 2
    out = core.sample(SampleRequest(8))
    assert isinstance(out, WireError) and out.reason == "rate_limited"  # online table still empty
    fill(core, 40, batch=10)
    b = sample_ok(core, SampleRequest(64, 4))
    assert not b.is_demo.any() and b.info == {"phase": 2, "prioritized": False, "live": b.info["live"]}
    check_rows_traceable(core, b)
    # A batch made in phase 1 that arrives late is still not stored.
    assert core.ingest(tmsg("w0", 4, rows=5, start=1000, phase=1), "w0") is None
    assert core.online.inserted == 40 and core.stats()["dropped"] == {"rehearsal_phase1": 5}
    with pytest.raises(ValueError, match="forward"):
        core.set_phase(1)
    assert core.handle_control({"cmd": "set_phase", "phase": 1})["ok"] is False
    core.set_phase(2)  # repeating phase 2 is fine
    assert core.phase == 2 and core.demo.digest() == digest


def test_rehearsal_phase2_demo_share_of_buffer_is_zero():
    """In rehearsal's phase 2 the demos are no longer sampled, so they are not in "the buffer"
    either: ``demo_share_buffer`` is 0, not demo.size / online.size (here 64 / 40 = 1.6, a share
    above 1, if the demos were counted above a total that leaves them out)."""
    core = make_core("rehearsal", demo=64, min_size=20)
    core.set_phase(2)
    fill(core, 40, batch=10)
    assert core.stats()["demo_share_buffer"] == 0.0


def test_dqfd_pretrains_on_its_demo_region_then_keeps_it_in_the_buffer():
    """dqfd = rehearsal's phase 1 (demos only, agent items dropped) + retention's buffer in phase 2."""
    core = make_core("dqfd", demo=200, capacity=1000, min_size=20)  # demo region: 10 % = 100 items
    assert core.phase == 1 and core.demo.size == 100 and core.online.capacity == 900
    b = sample_ok(core, SampleRequest(32, 2))
    assert b.is_demo.all() and b.info["phase"] == 1
    assert core.ingest(tmsg("w0", 0, rows=6), "w0") is None
    assert core.online.inserted == 0 and core.stats()["dropped"] == {"dqfd_phase1": 6}
    core.set_phase(2)
    fill(core, 100, batch=10)
    b = sample_ok(core, SampleRequest(500, 1))
    # Uniform over 100 demo + 100 online items: about half the rows are demos.
    assert 0.35 < b.is_demo.mean() < 0.65 and b.info["phase"] == 2
    check_rows_traceable(core, b)
    assert core.stats()["demo_share_buffer"] == 0.5
    with pytest.raises(ValueError, match="forward"):
        core.set_phase(1)


def test_a_request_without_next_obs_gets_the_same_rows_without_their_next_observations():
    """SampleRequest(next_obs=False) draws what the whole request draws (same seed, same rows) and
    leaves next_obs out: phase 1's demo rows alone, phase 2's mix of demo and online rows, and
    online rows alone; the reply's bytes decode to the same rows."""
    def pair(mode: str, **kw) -> tuple[ReplayCore, ReplayCore]:
        return make_core(mode, **kw), make_core(mode, **kw)

    cases = []
    whole, part = pair("dqfd", demo=200, capacity=1000, min_size=20)
    cases.append((whole, part))  # phase 1: every row a demo row
    whole2, part2 = pair("dqfd", demo=200, capacity=1000, min_size=20)
    for core in (whole2, part2):
        core.set_phase(2)
        fill(core, 100, batch=10)
    cases.append((whole2, part2))  # demo and online rows
    whole3, part3 = pair("none", min_size=10)
    for core in (whole3, part3):
        fill(core, 60)
    cases.append((whole3, part3))  # online rows alone
    for whole, part in cases:
        a = sample_ok(whole, SampleRequest(64, 2))
        b = sample_ok(part, SampleRequest(64, 2, next_obs=False))
        assert b.next_obs is None and a.next_obs is not None
        for name in BATCH_FIELDS:
            if name != "next_obs":
                assert np.array_equal(getattr(a, name), getattr(b, name)), name
        check_rows_traceable(whole, a)
        query = wire.encode_sample_request(SampleRequest(64, 2, next_obs=False))
        sent = wire.decode_batch(part.handle_sample_query(query), SCHEMA)
        assert sent.next_obs is None and len(sent.action) == 128
        d = sent.is_demo.astype(bool)
        assert np.array_equal(sent.obs[d], part.demo.obs[sent.index[d]])


def test_rehearsal_needs_demos():
    with pytest.raises(ValueError, match="replay.demo_paths"):
        make_core("rehearsal", demo=0)


@pytest.mark.parametrize("mode", ["none", "retention"])
def test_phases_exist_only_in_rehearsal(mode):
    core = make_core(mode, demo=200, capacity=1000)
    with pytest.raises(ValueError):
        core.set_phase(2)
    assert core.handle_control({"cmd": "set_phase", "phase": 2}) == {
        "ok": False, "error": f"phase 2 is not valid in demo_mode {mode}"}


@pytest.mark.parametrize("phase", [0, 3, -1, "x", None, [2]])
def test_bad_phase_values(phase):
    core = make_core("rehearsal", demo=8)
    reply = core.handle_control({"cmd": "set_phase", "phase": phase})
    assert reply["ok"] is False and "error" in reply and core.phase == 1


# --------------------------------------------------------------------------- ingest


@pytest.mark.parametrize("payload,reason", [(b"", "truncated"), (b"junk" * 5, "bad_magic"),
                                            (wire.encode_json({"a": 1}), "wrong_kind")])
def test_ingest_counts_garbage_by_reason(payload, reason):
    core = make_core()
    assert core.ingest(payload, "w0") == reason
    assert core.stats()["rejected"] == {reason: 1} and core.online.inserted == 0 and core.stats()["actors"] == {}


def test_ingest_refuses_schema_violations():
    core = make_core()
    bad_action = wire.encode_transitions(TransitionBatch.from_arrays(
        actor="w0", seq=0, weights_version=0, phase=0, env_steps=1, obs=np.zeros((1, 3), np.float32), action=[5],
        reward=[0], next_obs=np.zeros((1, 3), np.float32), terminated=[0], truncated=[0]))
    assert core.ingest(bad_action, "w0") == "bad_value"
    wrong_obs = wire.encode_transitions(TransitionBatch.from_arrays(
        actor="w0", seq=0, weights_version=0, phase=0, env_steps=1, obs=np.zeros((1, 4), np.float32), action=[0],
        reward=[0], next_obs=np.zeros((1, 4), np.float32), terminated=[0], truncated=[0]))
    assert core.ingest(wrong_obs, "w0") == "bad_shape"
    assert core.online.inserted == 0 and core.stats()["rejected"] == {"bad_value": 1, "bad_shape": 1}


def test_actor_mismatch():
    core = make_core()
    assert core.ingest(tmsg("w0"), "w1") == "actor_mismatch"
    assert core.online.inserted == 0 and core.stats()["actors"] == {}
    assert core.stats()["rejected"] == {"actor_mismatch": 1}
    assert core.ingest(tmsg("w0"), None) is None  # no key (in-process use): the header's actor counts
    assert core.online.inserted == 4


def test_per_actor_counters_and_seq_gaps():
    core = make_core(capacity=1000)
    # Seqs 2 and 3 missing when 4 arrives (counted lost); 3 then comes late (a worker's resend: no
    # longer lost, stored), 4 again (a duplicate: ignored, counted as such, not an error).
    expect = {0: None, 1: None, 4: None, 3: None, "4 again": "duplicate", 5: None}
    for key, reason in expect.items():
        seq = 4 if key == "4 again" else key
        msg = tmsg("w0", seq, rows=4, start=seq * 4, version=min(seq, 3), env_steps=(seq + 1) * 4)
        assert core.ingest(msg, "w0") == reason, key
    assert core.missing("w0") == [2]
    # First seen at seq 7: its 7 earlier batches (14 env steps before this one) never arrived here.
    assert core.ingest(tmsg("w1", 7, rows=2, start=500, env_steps=16), "w1") is None
    a = core.stats()["actors"]
    assert a["w0"] == {"batches": 5, "items": 20, "stored": 20, "last_seq": 5, "lost_batches": 1, "lost_items": 4,
                       "last_version": 3, "env_steps": 24, "duplicates": 1}
    assert a["w1"] == {"batches": 1, "items": 2, "stored": 2, "last_seq": 7, "lost_batches": 7, "lost_items": 14,
                       "last_version": 0, "env_steps": 16, "duplicates": 0}
    assert core.stats()["rejected"] == {}
    # The ring remembers which actor (index in order of appearance) and version made each item.
    assert core.online.actor[20] == 1 and core.online.version[8] == 3
    # Seq 2 comes too: nothing of w0 is lost any more; every env step it made is stored once.
    assert core.ingest(tmsg("w0", 2, rows=4, start=8, version=2, env_steps=12), "w0") is None
    w0 = core.stats()["actors"]["w0"]
    assert (w0["lost_batches"], w0["lost_items"], w0["stored"]) == (0, 0, 24) and core.missing("w0") == []


def test_too_many_actors(monkeypatch):
    monkeypatch.setattr(actor_ledger, "MAX_ACTORS", 2)
    core = make_core()
    assert core.ingest(tmsg("a"), "a") is None and core.ingest(tmsg("b"), "b") is None
    assert core.ingest(tmsg("c"), "c") == "too_many_actors"
    assert core.ingest(tmsg("a", 1), "a") is None
    assert set(core.stats()["actors"]) == {"a", "b"} and core.stats()["rejected"] == {"too_many_actors": 1}


def test_the_runs_own_workers_keep_their_places_however_many_other_names_arrive(monkeypatch):
    """A flood of other names fills the book of actors before a late worker's first batch: the
    worker still gets in (without its place, each of its batches was refused and the run stalled,
    chaos row stats-flood); other names share what is left, and are refused once that is full."""
    monkeypatch.setattr(actor_ledger, "MAX_ACTORS", 4)
    core = ReplayCore(ReplayConfig(capacity=1000, min_size=1, actor_idle_evict_s=600), SCHEMA,
                      own_actors=["w0", "w1"])
    assert core.ingest(tmsg("w0"), "w0") is None
    assert [core.ingest(tmsg(f"flood{i}"), f"flood{i}") for i in range(3)] == [None, None, "too_many_actors"]
    assert core.ingest(tmsg("w1"), "w1") is None  # the late worker: its place was kept
    assert core.ingest(tmsg("w1", 1), "w1") is None
    assert set(core.stats()["actors"]) == {"w0", "w1", "flood0", "flood1"}
    assert core.stats()["rejected"] == {"too_many_actors": 1}


@pytest.mark.parametrize("version", [2**31, 2**63, 10**30])
def test_ingest_huge_weights_version_never_raises_nor_stores_partially(version):
    """A huge ``weights_version`` never makes ``ingest`` raise: the batch is stored whole (the ring's
    version column is int64) or refused with nothing changed. Written half way, an OverflowError
    would leave rows in the ring and ``last_version`` at 2**31 (which satisfies any sync readiness),
    and in the service it would end the ingest thread, which has no handler: all ingestion would
    stop."""
    core = make_core()
    fill(core, 8, batch=4, actors=("w0",))
    before, actors = snapshot(core.online), core.stats()["actors"]
    reason = core.ingest(tmsg("w0", 2, rows=4, start=8, version=version), "w0")  # must not raise
    if reason is None:  # stored whole
        assert core.online.inserted == 12 and (core.online.version[8:12] == version).all()
        assert np.array_equal(core.online.obs[8:12, 0], np.arange(8, 12, dtype=np.float32))
    else:  # or refused, with nothing changed
        assert core.online.inserted == 8
        assert all(np.array_equal(v, getattr(core.online, k)) for k, v in before.items())
        assert core.stats()["actors"] == actors


def _reference(payload: bytes) -> TransitionBatch | None:
    try:
        return wire.decode_transitions(payload, SCHEMA)
    except WireError:
        return None


MUTATION = st.tuples(st.sampled_from(["flip", "set", "insert", "delete", "truncate"]), st.integers(0, 10**6),
                     st.integers(0, 255))


def _mutate(data: bytes, muts: list) -> bytes:
    buf = bytearray(data)
    hlen = struct.unpack_from("<I", data, 8)[0]
    for op, pos, arg in muts:
        if not buf:
            break
        # Positions mostly inside the header and array bytes (the envelope is covered in test_wire).
        i = min(12 + pos % max(len(buf) - 12, 1), len(buf) - 1) if pos % 4 else 12 + pos % max(hlen, 1)
        i = min(i, len(buf) - 1)
        if op == "flip":
            buf[i] ^= 1 << (arg % 8)
        elif op == "set":
            buf[i] = arg
        elif op == "insert":
            buf[i:i] = bytes([arg]) * (1 + arg % 3)
        elif op == "delete":
            del buf[i:i + 1 + arg % 4]
        else:
            del buf[i:]
    return bytes(buf)


@FUZZ
@given(st.lists(st.tuples(st.integers(1, 6), st.lists(MUTATION, max_size=3)), min_size=1, max_size=6))
def test_property_ingest_stores_whole_valid_batches_only(plan):
    core = make_core(capacity=16)
    start = 0
    for seq, (rows, muts) in enumerate(plan):
        payload = _mutate(tmsg("w0", seq, rows, start), muts) if muts else tmsg("w0", seq, rows, start)
        start += rows
        expected = _reference(payload)
        before, inserted = snapshot(core.online), core.online.inserted
        reason = core.ingest(payload)  # must never raise
        if expected is None:
            assert reason is not None
            assert core.online.inserted == inserted
            assert all(np.array_equal(v, getattr(core.online, k)) for k, v in before.items())
        else:
            assert reason is None
            n = len(expected)
            assert core.online.inserted == inserted + n
            keys = np.arange(inserted + max(0, n - 16), inserted + n)
            rows_ = keys % 16
            assert np.array_equal(core.online.obs[rows_], expected.obs[n - len(keys):])
            assert np.array_equal(core.online.action[rows_], expected.action[n - len(keys):])
            untouched = np.setdiff1d(np.arange(16), rows_)
            assert np.array_equal(core.online.obs[untouched], before["obs"][untouched])
    s = core.stats()
    assert sum(s["rejected"].values()) + sum(a["batches"] for a in s["actors"].values()) == len(plan)


# --------------------------------------------------------------------------- sync readiness


def test_sync_readiness_waits_for_every_listed_actor():
    core = make_core(capacity=1000)
    fill(core, 40, batch=10, actors=("w0", "w1"))  # version 0 from both
    req = SampleRequest(8, 2, min_version=1, actors=("w0", "w1"))
    out = core.sample(req)
    assert isinstance(out, WireError) and out.reason == "not_ready" and out.retry_after_ms == 2
    assert "w0" in out.detail and "w1" in out.detail
    core.ingest(tmsg("w0", 2, rows=4, start=40, version=1), "w0")
    out = core.sample(req)
    assert isinstance(out, WireError) and out.reason == "not_ready" and "w1" in out.detail and "'w0'" not in out.detail
    core.ingest(tmsg("w1", 2, rows=4, start=44, version=2), "w1")  # a newer version also counts
    assert isinstance(core.sample(req), wire.SampledBatch)
    assert core.stats()["requests"] == {"not_ready": 2, "served": 1}


def test_sync_readiness_edge_cases():
    core = make_core(capacity=1000)
    fill(core, 10, batch=10, actors=("w0",))
    assert core.sample(SampleRequest(4, min_version=0, actors=("w0", "ghost"))).reason == "not_ready"
    assert isinstance(core.sample(SampleRequest(4, min_version=0, actors=("w0",))), wire.SampledBatch)
    assert isinstance(core.sample(SampleRequest(4, min_version=0)), wire.SampledBatch)  # no actors listed
    assert isinstance(core.sample(SampleRequest(4, min_version=-1, actors=("ghost",))), wire.SampledBatch)
    # A rejected batch (actor mismatch) does not make its actor ready.
    core.ingest(tmsg("w2", 0, version=5), "w3")
    assert core.sample(SampleRequest(4, min_version=5, actors=("w2",))).reason == "not_ready"


def test_sync_readiness_comes_before_rate_limiting():
    core = make_core(capacity=1000, min_size=100)
    assert core.sample(SampleRequest(4, min_version=0, actors=("w0",))).reason == "not_ready"
    core.ingest(tmsg("w0"), "w0")
    assert core.sample(SampleRequest(4, min_version=0, actors=("w0",))).reason == "rate_limited"


def test_rehearsal_phase1_batches_count_for_readiness_although_dropped():
    core = make_core("rehearsal", demo=16)
    core.ingest(tmsg("w0", 0, version=3, phase=1), "w0")
    assert core.online.inserted == 0
    assert isinstance(core.sample(SampleRequest(4, min_version=3, actors=("w0",))), wire.SampledBatch)


# --------------------------------------------------------------------------- rate limiter


def test_rate_limiter_can_sample():
    rl = SampleToInsertRatio(samples_per_insert=2.0, min_size=10, capacity=100, tolerance=16)
    assert not rl.can_sample(size=9, inserts=9, samples=0, rows=1)
    assert rl.can_sample(size=10, inserts=10, samples=0, rows=16)  # 0 owed + 16 slack
    assert not rl.can_sample(size=10, inserts=10, samples=0, rows=17)
    assert rl.can_sample(size=20, inserts=20, samples=20, rows=16)  # owed 2 * 10 - 20 = 0
    assert not rl.can_sample(size=20, inserts=20, samples=21, rows=16)
    assert rl.can_sample(size=100, inserts=500, samples=0, rows=16)  # inserts count, not the table size
    free = SampleToInsertRatio(samples_per_insert=0.0, min_size=10, capacity=100)
    assert not free.can_sample(size=9, inserts=9, samples=0, rows=1)
    assert free.can_sample(size=10, inserts=10, samples=10**9, rows=10**6)


def test_rate_limiter_can_insert():
    rl = SampleToInsertRatio(samples_per_insert=2.0, min_size=10, capacity=100, tolerance=16)
    assert rl.can_insert(inserts=0, samples=0) and rl.can_insert(inserts=9, samples=0)
    assert rl.can_insert(inserts=18, samples=0)  # owed 16 <= 16
    assert not rl.can_insert(inserts=19, samples=0)  # owed 18 > 16: actors wait for the learner
    assert rl.can_insert(inserts=19, samples=2)
    assert SampleToInsertRatio(0.0, 10, 100).can_insert(inserts=10**9, samples=0)


def test_rate_limiter_refusals_and_state():
    with pytest.raises(ValueError, match="replay.min_size 101 exceeds"):
        SampleToInsertRatio(1.0, min_size=101, capacity=100)
    SampleToInsertRatio(1.0, min_size=100, capacity=100)
    with pytest.raises(ValueError):
        SampleToInsertRatio(-1.0, 1, 100)
    with pytest.raises(ValueError):
        SampleToInsertRatio(1.0, 1, 100, tolerance=-1)
    rl = SampleToInsertRatio(2.0, 10, 100, tolerance=16)
    rl.check_request(16)
    with pytest.raises(ValueError, match="tolerance"):
        rl.check_request(17)
    SampleToInsertRatio(0.0, 10, 100, tolerance=0).check_request(10**6)  # no ratio: any size
    assert rl.state(size=5, inserts=30, samples=4) == {
        "min_size": 10, "samples_per_insert": 2.0, "tolerance": 16, "size_ok": False,
        "rows_owed_to_learner": 36.0, "insert_ok": False}
    assert SampleToInsertRatio(0.0, 10, 100).state(size=10, inserts=10, samples=0)["rows_owed_to_learner"] is None


def test_core_applies_the_ratio():
    core = make_core(capacity=100, min_size=10, samples_per_insert=2.0, spi_tolerance=16)
    fill(core, 10, batch=10, actors=("w0",))
    sample_ok(core, SampleRequest(16))
    assert core.samples == 16
    out = core.sample(SampleRequest(8))
    assert isinstance(out, WireError) and out.reason == "rate_limited"
    fill(core, 4, batch=4, actors=("w1",))  # owed 2 * 4 - 16 = -8, + 16 slack = 8 rows
    sample_ok(core, SampleRequest(8))
    assert core.sample(SampleRequest(1)).reason == "rate_limited"
    assert core.insert_allowed()
    core.ingest(tmsg("w2", rows=20), "w2")  # 34 inserts: owed 2 * 24 - 24 = 24 > 16
    assert not core.insert_allowed()
    assert core.stats()["rate_limiter"]["insert_ok"] is False


def test_request_larger_than_tolerance():
    core = make_core(capacity=100, min_size=1, samples_per_insert=1.0, spi_tolerance=64)
    out = core.sample(SampleRequest(32, 3))
    assert isinstance(out, WireError) and out.reason == "request_too_large" and out.retry_after_ms == 0
    reply = core.handle_sample_query(wire.encode_sample_request(SampleRequest(65)))
    err = wire.decode_error(reply)
    assert err.reason == "request_too_large" and err.retry_after_ms == 0


# --------------------------------------------------------------------------- bytes in, bytes out


def test_handle_sample_query_serves_batches():
    core = make_core(capacity=1000)
    fill(core, 100)
    reply = core.handle_sample_query(wire.encode_sample_request(SampleRequest(16, 3)))
    assert wire.peek_kind(reply) == wire.Kind.BATCH
    b = wire.decode_batch(reply, SCHEMA)
    assert b.num_batches == 3 and b.obs.shape == (48, 3) and b.index.dtype == np.int64
    check_rows_traceable(core, b)


def test_handle_sample_query_errors():
    core = make_core(capacity=1000, min_size=50)
    err = wire.decode_error(core.handle_sample_query(b"nonsense-nonsense"))
    assert err.reason == "bad_request" and err.retry_after_ms == 0
    zero = wire.encode(wire.Kind.SAMPLE_REQUEST, {"batch_size": 0, "num_batches": 1, "min_version": -1, "actors": []})
    assert wire.decode_error(core.handle_sample_query(zero)).reason == "bad_request"
    assert wire.decode_error(core.handle_sample_query(wire.encode_json({}))).reason == "bad_request"
    assert core.stats()["rejected"] == {"bad_request:bad_magic": 1, "bad_request:bad_request": 1,
                                        "bad_request:wrong_kind": 1}
    err = wire.decode_error(core.handle_sample_query(wire.encode_sample_request(SampleRequest(8))))
    assert err.reason == "rate_limited" and err.retry_after_ms == 5
    err = wire.decode_error(core.handle_sample_query(
        wire.encode_sample_request(SampleRequest(8, min_version=0, actors=("w0",)))))
    assert err.reason == "not_ready" and err.retry_after_ms == 2


def test_handle_control_commands():
    core = make_core("rehearsal", demo=8)
    assert core.handle_control({"cmd": "set_phase", "phase": 2}) == {"ok": True, "phase": 2}
    assert core.handle_control({"cmd": "set_phase", "phase": "2"}) == {"ok": True, "phase": 2}
    reply = core.handle_control({"cmd": "stats"})
    assert reply["ok"] is True and reply["stats"]["phase"] == 2 and reply["stats"]["mode"] == "rehearsal"
    assert core.handle_control({"cmd": "reboot"}) == {"ok": False, "error": "unknown command 'reboot'"}
    assert core.handle_control({}) == {"ok": False, "error": "unknown command None"}


def test_stats_shape_is_json_and_complete():
    core = make_core("retention", demo=200, capacity=1000)
    fill(core, 300)
    sample_ok(core, SampleRequest(32))
    s = core.stats()
    assert set(s) == {"mode", "phase", "http_url", "uptime_s", "actors_total", "tables", "demo_in_buffer",
                      "demo_share_buffer", "demo_share_recent_samples",
                      "sampled_rows", "sampled_demo_rows", "requests", "rejected", "dropped", "actors", "rates",
                      "rate_limiter", "checkpoint", "wal", "sampler", "obs_shape", "obs_dtype", "n_actions"}
    assert s["wal"] == {"mode": "off"}  # a bare core has no write-ahead log (the server gives it one)
    assert s["tables"]["online"] == {"size": 300, "capacity": 900, "inserted": 300, "bytes": core.online.nbytes}
    assert s["tables"]["demo"]["sha256"] == "d" * 64
    # stats travel as a JSON message: it must encode and decode unchanged
    assert wire.decode_json(wire.encode_json(s)) == s


def test_demo_digest_is_sha256_of_the_arrays():
    t = demo_table(5)
    h = hashlib.sha256()
    for a in (t.obs, t.action, t.reward, t.next_obs, t.terminated, t.steps):
        h.update(a.tobytes())
    assert t.digest() == h.hexdigest()
    assert t.subset(np.arange(5)).digest() == t.digest() != t.subset(np.arange(4)).digest()
