"""The replay server's fast ingest and sample paths against straightforward references: the ring's
slice inserts against a fancy-index scatter, the all-online gather against the stored rows, the
cached sample request, and ingest from payload views (stored rows are copies).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.storage import DemoTable, RingTable
from laneshift.wire import SampleRequest, TransitionBatch, TransitionSchema

SCHEMA = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=5)
FUZZ = settings(derandomize=True, database=None, deadline=None, max_examples=150,
                suppress_health_check=[HealthCheck.too_slow])
COLUMNS = ("obs", "next_obs", "action", "reward", "terminated", "truncated", "steps", "actor", "version", "key", "seq")


def batch(rows: int, start: int, seq: int = 0, version: int = 0) -> TransitionBatch:
    obs = np.zeros((rows, 3), np.float32)
    obs[:, 0] = np.arange(start, start + rows)
    return TransitionBatch.from_arrays(actor="w0", seq=seq, weights_version=version, phase=0, env_steps=start + rows,
                                       obs=obs, action=np.arange(rows) % 5, reward=np.arange(rows, dtype=np.float32),
                                       next_obs=obs + 0.5, terminated=np.arange(rows) % 2, truncated=np.zeros(rows),
                                       steps=1 + np.arange(rows) % 3)


def reference_insert(t: RingTable, b: TransitionBatch, actor_index: int) -> np.ndarray:
    """The ring insert as it was written before the slice copies: one fancy-index scatter per column."""
    n = len(b)
    skip = max(0, n - t.capacity)
    keys = np.arange(t.inserted + skip, t.inserted + n, dtype=np.int64)
    rows = keys % t.capacity
    for name in ("obs", "next_obs", "action", "reward", "terminated", "truncated", "steps"):
        getattr(t, name)[rows] = getattr(b, name)[skip:]
    t.actor[rows], t.version[rows], t.key[rows], t.seq[rows] = actor_index, b.weights_version, keys, b.seq
    t.inserted += n
    return keys


@FUZZ
@given(st.integers(1, 40), st.lists(st.integers(1, 90), min_size=1, max_size=25))
def test_property_ring_insert_matches_the_scatter_reference(capacity, sizes):
    fast, ref = RingTable(capacity, (3,), "float32"), RingTable(capacity, (3,), "float32")
    for i, n in enumerate(sizes):
        b = batch(n, fast.inserted, seq=i, version=i * 3)
        assert np.array_equal(fast.insert(b, i % 4), reference_insert(ref, b, i % 4))
        assert fast.inserted == ref.inserted
        for name in COLUMNS:
            assert np.array_equal(getattr(fast, name), getattr(ref, name)), name


def make_core(capacity: int = 64) -> ReplayCore:
    return ReplayCore(ReplayConfig(capacity=capacity, min_size=1, samples_per_insert=0.0), SCHEMA)


def fill(core: ReplayCore, total: int, rows: int = 7) -> None:
    seq = 0
    while core.online.inserted < total:
        assert core.ingest(wire.encode_transitions(batch(rows, core.online.inserted, seq)), "w0") is None
        seq += 1


@pytest.mark.parametrize("total", [10, 64, 200])
def test_all_online_gather_returns_the_stored_rows(total):
    core = make_core()
    fill(core, total)
    for nb in (1, 3):
        out = core.sample(SampleRequest(16, nb))
        assert isinstance(out, wire.SampledBatch)
        assert not out.is_demo.any() and out.action.shape == (16 * nb,)
        rows = out.index % core.online.capacity
        assert np.array_equal(core.online.key[rows], out.index)
        assert ((out.index >= core.online.tail) & (out.index < core.online.inserted)).all()
        assert np.array_equal(out.obs[:, 0], out.index.astype(np.float32))  # obs[:, 0] is the key
        for name in ("obs", "next_obs", "action", "reward", "terminated", "steps"):
            assert np.array_equal(getattr(out, name), getattr(core.online, name)[rows]), name
        assert (out.weight == 1).all()


def test_mixed_gather_returns_the_stored_demo_and_online_rows():
    """Retention: demo rows come from the demo table, online rows from the ring's records."""
    rows = 40
    obs = np.zeros((rows, 3), np.float32)
    obs[:, 0] = -1 - np.arange(rows)  # demo obs[:, 0] < 0, online >= 0
    demo = DemoTable(obs, np.arange(rows) % 5, np.linspace(-1, 0, rows).astype(np.float32), obs + 0.25,
                     (np.arange(rows) % 2).astype(np.uint8), "sha", {}, (1 + np.arange(rows) % 2).astype(np.uint8))
    core = ReplayCore(ReplayConfig(capacity=64, min_size=1, samples_per_insert=0.0, demo_mode="retention",
                                   demo_ratio=0.25), SCHEMA, demo)
    fill(core, 150)
    out = core.sample(SampleRequest(64, 2))
    assert isinstance(out, wire.SampledBatch)
    d = out.is_demo.astype(bool)
    assert d.any() and (~d).any()
    online_rows = out.index[~d] % core.online.capacity
    assert np.array_equal(core.online.key[online_rows], out.index[~d])
    for name in ("obs", "next_obs", "action", "reward", "terminated", "steps"):
        assert np.array_equal(getattr(out, name)[d], getattr(core.demo, name)[out.index[d]]), name
        assert np.array_equal(getattr(out, name)[~d], getattr(core.online, name)[online_rows]), name
    assert (out.obs[d, 0] < 0).all() and np.array_equal(out.obs[~d, 0], out.index[~d].astype(np.float32))


def test_sample_query_cache_serves_repeats_and_still_refuses_bad_requests():
    core = make_core()
    fill(core, 100)
    req = wire.encode_sample_request(SampleRequest(8))
    for _ in range(3):
        assert wire.decode_batch(core.handle_sample_query(req), SCHEMA).action.shape == (8,)
    other = wire.encode_sample_request(SampleRequest(4, 2))
    assert wire.decode_batch(core.handle_sample_query(other), SCHEMA).num_batches == 2
    bad = bytearray(req)
    bad[0] ^= 0xFF
    reply = core.handle_sample_query(bytes(bad))
    assert wire.peek_kind(reply) == wire.Kind.ERROR
    assert core.stats()["rejected"] == {"bad_request:bad_magic": 1}
    assert wire.decode_batch(core.handle_sample_query(req), SCHEMA).action.shape == (8,)
    assert wire.decode_batch(core.handle_sample_query(memoryview(req)), SCHEMA).action.shape == (8,)


def test_ingest_stores_copies_of_the_payload():
    core = make_core()
    payload = bytearray(wire.encode_transitions(batch(5, 0)))
    assert core.ingest(payload, "w0") is None
    stored = core.online.obs[:5].copy()
    payload[-100:] = b"\x7f" * 100  # the network buffer reused after ingest returned
    assert np.array_equal(core.online.obs[:5], stored)
    assert np.array_equal(stored[:, 0], np.arange(5, dtype=np.float32))


def test_malformed_messages_are_counted_and_never_stored():
    core = make_core()
    good = wire.encode_transitions(batch(4, 0))
    nan_obs = batch(4, 0)
    nan_obs.obs[1, 1] = np.nan
    for payload in (good[:-1], good + b"\0", wire.encode_transitions(nan_obs), b"", b"LSHF" + good[4:12]):
        assert core.ingest(payload, "w0") is not None
    assert core.online.inserted == 0
    assert sum(core.stats()["rejected"].values()) == 5
    assert core.ingest(good, "w0") is None and core.online.inserted == 4
