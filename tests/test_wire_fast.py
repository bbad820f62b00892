"""The wire's fast paths (``laneshift.wire.fastpath``: ``fast_transitions``, ``fast_batch``,
``fast_encode_batch``) against the generic checks: same results on every valid message, and never a
message accepted that the generic path refuses (mutated messages, hand-made headers, values at the
edges).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laneshift import wire
from laneshift.wire import (MAGIC, WIRE_VERSION, Kind, SampledBatch, TransitionBatch, TransitionSchema, WireError,
                            decode_batch, decode_transitions, encode, encode_batch, encode_transitions)
from laneshift.wire import fastpath, sampling
from laneshift.wire import transitions as transitions_codec
from laneshift.wire.batches import BATCH_FIELDS

FUZZ = settings(derandomize=True, database=None, deadline=None, max_examples=300,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SCHEMAS = [TransitionSchema((3,), "float32", 9), TransitionSchema((82,), "float32", 5),
           TransitionSchema((2, 3), "float64", 4), TransitionSchema((4,), "float16", 3),
           TransitionSchema((2, 5, 5), "uint8", 7)]


def arrays_for(schema: TransitionSchema, rows: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    shape = (rows, *schema.obs_shape)
    if np.dtype(schema.obs_dtype).kind == "f":
        obs = rng.normal(size=shape).astype(schema.obs_dtype)
    else:
        obs = rng.integers(0, 255, size=shape).astype(schema.obs_dtype)
    return {"obs": obs, "action": rng.integers(0, schema.n_actions, rows), "reward": rng.normal(size=rows),
            "next_obs": obs[::-1].copy(), "terminated": rng.integers(0, 2, rows), "truncated": rng.integers(0, 2, rows),
            "steps": rng.integers(1, 4, rows)}


def batch_for(schema: TransitionSchema, rows: int, seed: int = 0, **kw) -> TransitionBatch:
    fields = {"actor": "w-0", "seq": seed, "weights_version": 3, "phase": 0, "env_steps": 10 + rows,
              **arrays_for(schema, rows, seed)}
    fields.update(kw)
    return TransitionBatch.from_arrays(**fields)


def same(a: TransitionBatch, b: TransitionBatch) -> None:
    for f in ("actor", "seq", "weights_version", "phase", "env_steps", "extra"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("obs", "action", "reward", "next_obs", "terminated", "truncated", "steps"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=True), f


def generic_or_reason(data: bytes, schema: TransitionSchema) -> TransitionBatch | str:
    try:
        return transitions_codec._checked_transitions(data, schema)
    except WireError as exc:
        return exc.reason


def check_subset(data: bytes, schema: TransitionSchema) -> None:
    """The fast path accepts only what the generic one accepts, with the same content; the public
    decoder's answer (batch or reason) is the generic one."""
    generic = generic_or_reason(data, schema)
    for copy in (True, False):
        fast = fastpath.fast_transitions(data, schema, copy)
        if fast is not None:
            assert not isinstance(generic, str), f"fast path accepted what the generic path refuses: {generic}"
            same(fast, generic)
    try:
        public: TransitionBatch | str = decode_transitions(data, schema)
    except WireError as exc:
        public = exc.reason
    if isinstance(generic, str):
        assert public == generic
    else:
        same(public, generic)


@pytest.mark.parametrize("schema", SCHEMAS, ids=lambda s: f"{s.obs_dtype}{s.obs_shape}")
@pytest.mark.parametrize("rows", [1, 2, 7, 32, 256])
def test_canonical_messages_take_the_fast_path_with_the_generic_result(schema, rows):
    data = encode_transitions(batch_for(schema, rows, extra={"episode": [1, 2]}))
    views = fastpath.fast_transitions(data, schema, copy=False)
    assert views is not None
    same(views, transitions_codec._checked_transitions(data, schema))
    copied = fastpath.fast_transitions(data, schema, copy=True)
    # A copy is made in one block only where every array lands aligned in it; else the generic path copies.
    assert (copied is not None) == fastpath._transitions_layout(schema, rows).aligned
    same(decode_transitions(data, schema), views)
    for arr in (decode_transitions(data, schema).obs, decode_transitions(data, schema).action):
        assert arr.flags.aligned and arr.flags.writeable


def test_copy_modes():
    schema = SCHEMAS[1]
    data = encode_transitions(batch_for(schema, 32))
    views = decode_transitions(data, schema, copy=False)
    assert not views.obs.flags.writeable  # views of immutable bytes
    assert np.shares_memory(views.obs, np.frombuffer(data, np.uint8))
    copied = decode_transitions(data, schema)
    assert copied.obs.flags.writeable and copied.action.flags.writeable
    assert not np.shares_memory(copied.obs, np.frombuffer(data, np.uint8))
    buf = bytearray(data)
    kept = decode_transitions(buf, schema)
    before = kept.obs.copy()
    buf[-200:] = b"\xff" * 200
    assert np.array_equal(kept.obs, before)


@FUZZ
@given(st.sampled_from(range(len(SCHEMAS))), st.integers(1, 40), st.integers(0, 2**31),
       st.lists(st.tuples(st.sampled_from(["envelope", "header", "arrays", "end"]), st.integers(0, 10**6),
                          st.integers(0, 255)), min_size=1, max_size=4))
def test_property_mutated_messages(which, rows, seed, mutations):
    schema = SCHEMAS[which]
    data = bytearray(encode_transitions(batch_for(schema, rows, seed % 1000, seq=seed)))
    hlen = struct.unpack_from("<I", data, 8)[0]
    for region, pos, value in mutations:
        lo, hi = {"envelope": (0, 12), "header": (12, 12 + hlen), "arrays": (12 + hlen, len(data)),
                  "end": (max(0, len(data) - 16), len(data))}[region]
        data[lo + pos % max(hi - lo, 1)] = value
    check_subset(bytes(data), schema)


@FUZZ
@given(st.sampled_from(["actor", "seq", "extra", "arrays", "obs", "shape", "dtype", "<f4", "[", "]", "{", "}", ",",
                        ":", '"', "32", "82"]), st.binary(max_size=6), st.integers(0, 5))
def test_property_header_splices(token, junk, which):
    schema = SCHEMAS[1]
    msg = encode_transitions(batch_for(schema, 32))
    hlen = struct.unpack_from("<I", msg, 8)[0]
    head = msg[12:12 + hlen]
    positions = [i + len(token) for i in range(len(head)) if head.startswith(token.encode(), i)]
    if not positions:
        return
    p = positions[which % len(positions)]
    new_head = head[:p] + junk + head[p:]
    check_subset(struct.pack("<4sHBBI", MAGIC, WIRE_VERSION, 1, 0, len(new_head)) + new_head + msg[12 + hlen:], schema)


def with_header(data: bytes, text: str) -> bytes:
    """``data`` with its header replaced by ``text`` (the array bytes kept)."""
    hlen = struct.unpack_from("<I", data, 8)[0]
    head = text.encode()
    return struct.pack("<4sHBBI", MAGIC, WIRE_VERSION, 1, 0, len(head)) + head + data[12 + hlen:]


def header_of(data: bytes) -> str:
    return data[12:12 + struct.unpack_from("<I", data, 8)[0]].decode()


def test_hand_made_headers_around_the_fixed_table():
    schema = SCHEMAS[0]
    data = encode_transitions(batch_for(schema, 2))
    head = header_of(data)
    cut = head.rfind(',"arrays":[')
    table = head[cut:]
    cases = {
        "empty prefix": "{" + table,
        "prefix of spaces": "{ " + table,
        "table twice": head[:cut] + table[:-1] + table,
        "no comma": head[:cut] + table[1:],
        "float seq": head.replace('"seq":0', '"seq":0.0'),
        "bool seq": head.replace('"seq":0', '"seq":true'),
        "seq at the bound": head.replace('"seq":0', f'"seq":{2**53}'),
        "negative phase": head.replace('"phase":0', '"phase":-1'),
        "actor with newline": head.replace('"actor":"w-0"', '"actor":"w-0\\n"'),
        "extra a list": head.replace('"extra":{}', '"extra":[]'),
        "extra missing": head.replace(',"extra":{}', ""),
        "NaN in extra": head.replace('"extra":{}', '"extra":{"x":NaN}'),
        "float overflow in extra": head.replace('"extra":{}', '"extra":{"x":1e999}'),
        "arrays earlier too": head[:cut] + ',"arrays":[]' + table,
        "trailing space": head + " ",
        "leading space": " " + head,
        "table in a string": '{"actor":"w-0' + table.replace('"', '\\"')[:-1] + '"}',
        "shape as float": head.replace('"shape":[2]', '"shape":[2.0]', 1),
        "shape as true": head.replace('"shape":[2,3]', '"shape":[2,3.0]'),
    }
    for name, text in cases.items():
        check_subset(with_header(data, text), schema)
    assert fastpath.fast_transitions(with_header(data, "{" + table), schema, True) is None
    assert fastpath.fast_transitions(with_header(data, "{ " + table), schema, True) is None
    with pytest.raises(WireError):
        decode_transitions(with_header(data, "{" + table), schema)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning", "ignore:invalid value:RuntimeWarning")
@pytest.mark.parametrize("obs_dtype", ["float16", "float32", "float64"])
def test_large_finite_values_are_accepted_and_non_finite_refused(obs_dtype):
    """A float sum can overflow on finite values: that must not refuse the batch."""
    schema = TransitionSchema((64,), obs_dtype, 3)
    big = np.finfo(obs_dtype).max
    obs = np.full((8, 64), big, obs_dtype)
    data = encode_transitions(batch_for(schema, 8, obs=obs, next_obs=-obs))
    assert fastpath.fast_transitions(data, schema, True) is not None
    for bad in (np.nan, np.inf, -np.inf):
        for field in ("obs", "next_obs"):
            arr = obs.copy()
            arr[5, 7] = bad
            msg = encode_transitions(batch_for(schema, 8, **{field: arr}))
            check_subset(msg, schema)
            with pytest.raises(WireError, match="non_finite"):
                decode_transitions(msg, schema)
    reward = np.zeros(8, np.float32)
    reward[7] = np.nan
    with pytest.raises(WireError, match="non_finite"):
        decode_transitions(encode_transitions(batch_for(schema, 8, reward=reward)), schema)


def test_value_rules_on_the_fast_path():
    schema = SCHEMAS[0]

    header = {"actor": "w0", "seq": 0, "weights_version": 0, "phase": 0, "env_steps": 2, "extra": {}}
    good = {"obs": np.zeros((2, 3), np.float32), "action": np.array([0, 1]), "reward": np.zeros(2, np.float32),
            "next_obs": np.zeros((2, 3), np.float32), "terminated": np.zeros(2, np.uint8),
            "truncated": np.zeros(2, np.uint8), "steps": np.ones(2, np.uint8)}

    def reason(**kw) -> str:
        data = encode(Kind.TRANSITIONS, header, {**good, **kw})
        check_subset(data, schema)
        try:
            decode_transitions(data, schema)
        except WireError as exc:
            return exc.reason
        return "ok"

    assert reason() == "ok"
    assert reason(action=np.array([0, 8])) == "ok"
    assert reason(action=np.array([0, 9])) == "bad_value"
    assert reason(action=np.array([-1, 0])) == "bad_value"
    assert reason(action=np.array([-(2**63), 0])) == "bad_value"
    assert reason(terminated=np.array([0, 2], np.uint8)) == "bad_value"
    assert reason(truncated=np.array([1, 255], np.uint8)) == "bad_value"
    assert reason(steps=np.array([1, 0], np.uint8)) == "bad_value"
    assert reason(action=np.array([0, 1], np.int32)) == "bad_dtype"  # another table: generic path


def test_layout_cache_stays_bounded():
    schema = SCHEMAS[0]
    for rows in range(1, fastpath._MAX_LAYOUTS + 40):
        assert fastpath.fast_transitions(encode_transitions(batch_for(schema, rows)), schema, False) is not None
        assert len(fastpath._LAYOUTS) <= fastpath._MAX_LAYOUTS


# --------------------------------------------------------------------------- batches


def sampled(schema: TransitionSchema, rows: int, nb: int = 1, seed: int = 0) -> SampledBatch:
    a = arrays_for(schema, rows, seed)
    return SampledBatch(obs=a["obs"], action=a["action"].astype(np.int64), reward=a["reward"].astype(np.float32),
                        next_obs=a["next_obs"], terminated=a["terminated"].astype(np.uint8),
                        steps=a["steps"].astype(np.uint8), is_demo=(np.arange(rows) % 2).astype(np.uint8),
                        index=np.arange(rows, dtype=np.int64) * 7, weight=np.linspace(0.1, 1, rows).astype(np.float32),
                        num_batches=nb, info={"phase": 2, "prioritized": True})


def generic_encode(batch: SampledBatch) -> bytes:
    return encode(Kind.BATCH, {"num_batches": batch.num_batches, "info": batch.info},
                  {k: getattr(batch, k) for k in BATCH_FIELDS})


@pytest.mark.parametrize("schema", SCHEMAS, ids=lambda s: f"{s.obs_dtype}{s.obs_shape}")
@pytest.mark.parametrize("rows,nb", [(1, 1), (6, 2), (256, 1), (1024, 4)])
def test_batch_fast_paths_match_the_generic_ones(schema, rows, nb):
    batch = sampled(schema, rows, nb)
    data = encode_batch(batch)
    assert fastpath.fast_encode_batch(batch) == data == generic_encode(batch)
    fast = fastpath.fast_batch(data, schema)
    # One block copy only where every array lands aligned in it (the learner hands them to torch).
    assert (fast is not None) == fastpath._batch_layout(schema.obs_shape, schema.obs_dtype, rows).aligned
    if fast is None:
        return
    slow = sampling._checked_batch(data, schema)
    assert fast.num_batches == slow.num_batches == nb and fast.info == slow.info
    for k in BATCH_FIELDS:
        x, y = getattr(fast, k), getattr(slow, k)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), k
        assert x.flags.writeable and x.flags.aligned


def test_a_batch_of_record_fields_encodes_as_its_columns():
    """The replay server gathers whole records (``storage.record_dtype``) and hands encode_batch
    their fields: strided views, written into the message as the same bytes as their copies."""
    schema = SCHEMAS[1]
    batch = sampled(schema, 32, 2)
    rec = np.zeros(32, [("obs", "<f4", schema.obs_shape), ("next_obs", "<f4", schema.obs_shape), ("action", "<i8"),
                        ("reward", "<f4"), ("terminated", "|u1"), ("steps", "|u1")])
    for name in rec.dtype.names:
        rec[name] = getattr(batch, name)
    views = SampledBatch(**{**batch.__dict__, **{name: rec[name] for name in rec.dtype.names}})
    assert not views.obs.flags.c_contiguous
    data = encode_batch(views)
    assert data == generic_encode(batch) == encode_batch(batch)
    back = wire.decode_batch(data, schema)
    for k in BATCH_FIELDS:
        assert np.array_equal(getattr(back, k), getattr(batch, k)), k


def test_encode_batch_falls_back_for_other_forms():
    schema = SCHEMAS[1]
    batch = sampled(schema, 8)
    odd = [dict(obs=np.asfortranarray(np.ones((8, 82), np.float32))[:, :]),
           dict(obs=np.ones((16, 82), np.float32)[::2]),  # not contiguous
           dict(reward=batch.reward.astype(">f4")), dict(index=batch.index.astype(np.int32)),
           dict(action=list(range(8)))]
    for change in odd:
        other = SampledBatch(**{**batch.__dict__, **change})
        assert encode_batch(other) == generic_encode(other)


@FUZZ
@given(st.integers(1, 40), st.integers(1, 4),
       st.lists(st.tuples(st.sampled_from(["envelope", "header", "arrays"]), st.integers(0, 10**6),
                          st.integers(0, 255)), min_size=1, max_size=4))
def test_property_mutated_batches(rows, nb, mutations):
    schema = SCHEMAS[0]
    data = bytearray(encode_batch(sampled(schema, rows * nb, nb)))
    hlen = struct.unpack_from("<I", data, 8)[0]
    for region, pos, value in mutations:
        lo, hi = {"envelope": (0, 12), "header": (12, 12 + hlen), "arrays": (12 + hlen, len(data))}[region]
        data[lo + pos % max(hi - lo, 1)] = value
    data = bytes(data)
    try:
        slow: SampledBatch | str = sampling._checked_batch(data, schema)
    except WireError as exc:
        slow = exc.reason
    fast = fastpath.fast_batch(data, schema)
    if fast is not None:
        assert not isinstance(slow, str), slow
        for k in BATCH_FIELDS:
            assert np.array_equal(getattr(fast, k), getattr(slow, k), equal_nan=True)
    try:
        public: SampledBatch | str = decode_batch(data, schema)
    except WireError as exc:
        public = exc.reason
    assert isinstance(public, str) == isinstance(slow, str) and (not isinstance(slow, str) or public == slow)


def test_batch_rules_on_the_fast_path():
    schema = SCHEMAS[0]
    data = encode_batch(sampled(schema, 6, 2))
    head = header_of(data)
    for text in (head.replace('"num_batches":2', '"num_batches":4'), head.replace('"num_batches":2', '"num_batches":0'),
                 head.replace('"num_batches":2', '"num_batches":true'),
                 head.replace('"num_batches":2', '"num_batches":2.0')):
        hlen = struct.unpack_from("<I", data, 8)[0]
        msg = struct.pack("<4sHBBI", MAGIC, WIRE_VERSION, 4, 0, len(text)) + text.encode() + data[12 + hlen:]
        assert fastpath.fast_batch(msg, schema) is None
        with pytest.raises(WireError):
            decode_batch(msg, schema)
    steps0 = sampled(schema, 6, 2)
    steps0.steps[3] = 0
    with pytest.raises(WireError, match="bad_value"):
        decode_batch(encode_batch(steps0), schema)
    json.loads(head)  # the header the tests edit is plain JSON
