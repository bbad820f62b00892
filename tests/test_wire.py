"""The wire contract (``laneshift.wire``): round trips, every validation rule, safetensors interop,
key expressions, and property tests that nothing but ``WireError`` ever escapes a decoder.

Everything here is pure (numpy + the standard library + safetensors + hypothesis): no zenoh, no
torch, no sleeps. Hypothesis runs derandomized without a database, so every run is identical.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest
import safetensors.numpy as stn
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laneshift import wire
from laneshift.wire import (
    MAGIC,
    MAX_BATCH_ROWS,
    MAX_HEADER_BYTES,
    MAX_MESSAGE_BYTES,
    WIRE_VERSION,
    Kind,
    SampledBatch,
    SampleRequest,
    TransitionBatch,
    TransitionSchema,
    Weights,
    WireError,
    decode,
    decode_batch,
    decode_error,
    decode_json,
    decode_sample_request,
    decode_transitions,
    decode_weights,
    encode,
    encode_batch,
    encode_error,
    encode_json,
    encode_sample_request,
    encode_transitions,
    encode_weights,
    peek_kind,
    safetensors_dumps,
    safetensors_loads,
)
from laneshift.wire import envelope as envelope_module
from laneshift.wire.batches import BATCH_FIELDS

SCHEMA = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=9)
FUZZ = settings(derandomize=True, database=None, deadline=None, max_examples=300,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
DOC = Path(__file__).resolve().parents[1] / "docs" / "wire.md"


# --------------------------------------------------------------------------- helpers


def batch_arrays(rows: int = 2, obs_shape: tuple[int, ...] = (3,), obs_dtype: str = "float32") -> dict[str, np.ndarray]:
    rng = np.random.default_rng(rows)
    if np.dtype(obs_dtype).kind == "f":
        obs = rng.normal(size=(rows, *obs_shape)).astype(obs_dtype)
    else:
        obs = rng.integers(0, 255, size=(rows, *obs_shape)).astype(obs_dtype)
    return {"obs": obs, "action": (np.arange(rows) % 9).astype(np.int64),
            "reward": rng.normal(size=rows).astype(np.float32), "next_obs": obs[::-1].copy(),
            "terminated": (np.arange(rows) % 2).astype(np.uint8), "truncated": np.zeros(rows, np.uint8),
            "steps": (1 + np.arange(rows) % 3).astype(np.uint8)}


def make_batch(rows: int = 2, **kw) -> TransitionBatch:
    fields = {"actor": "w0", "seq": 0, "weights_version": 0, "phase": 0, "env_steps": rows, **batch_arrays(rows)}
    fields.update(kw)
    return TransitionBatch.from_arrays(**fields)


def tmsg(header: dict | None = None, arrays: dict | None = None, drop: tuple[str, ...] = ()) -> bytes:
    """A TRANSITIONS message built with the generic encoder, so fields can be made invalid."""
    h = {"actor": "w0", "seq": 0, "weights_version": 0, "phase": 0, "env_steps": 2, "extra": {}}
    h.update(header or {})
    a = batch_arrays(2)
    a.update(arrays or {})
    for name in drop:
        (h if name in h else a).pop(name)
    return encode(Kind.TRANSITIONS, h, a)


def envelope(kind: int = 1, head: bytes | dict = b"{}", body: bytes = b"", *, magic: bytes = MAGIC,
             version: int = WIRE_VERSION, reserved: int = 0, hlen: int | None = None) -> bytes:
    """Hand-made envelope: every byte under the test's control."""
    if isinstance(head, dict):
        head = json.dumps(head).encode()
    return struct.pack("<4sHBBI", magic, version, kind, reserved, len(head) if hlen is None else hlen) + head + body


def reason_of(fn, *args) -> str:
    with pytest.raises(WireError) as info:
        fn(*args)
    return info.value.reason


def check_batch_fits(batch: TransitionBatch, schema: TransitionSchema) -> None:
    """An independent statement of what a decoded batch must satisfy."""
    rows = len(batch)
    assert 1 <= rows <= schema.max_rows
    assert wire.NAME.fullmatch(batch.actor)
    for v in (batch.seq, batch.weights_version, batch.phase, batch.env_steps):
        assert isinstance(v, int) and not isinstance(v, bool) and v >= 0
    assert isinstance(batch.extra, dict)
    for name in ("obs", "next_obs"):
        arr = getattr(batch, name)
        assert arr.shape == (rows, *schema.obs_shape) and arr.dtype.str == schema.obs_dtype
        if arr.dtype.kind == "f":
            assert np.isfinite(arr).all()
    for name, code in (("action", "<i8"), ("reward", "<f4"), ("terminated", "|u1"), ("truncated", "|u1"),
                       ("steps", "|u1")):
        arr = getattr(batch, name)
        assert arr.shape == (rows,) and arr.dtype.str == code
    assert (batch.steps >= 1).all()
    assert ((batch.action >= 0) & (batch.action < schema.n_actions)).all()
    assert np.isin(batch.terminated, (0, 1)).all() and np.isin(batch.truncated, (0, 1)).all()
    assert np.isfinite(batch.reward).all()


def assert_same_batch(a: TransitionBatch, b: TransitionBatch) -> None:
    for f in ("actor", "seq", "weights_version", "phase", "env_steps", "extra"):
        assert getattr(a, f) == getattr(b, f), f
    for f in ("obs", "action", "reward", "next_obs", "terminated", "truncated", "steps"):
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), f


# --------------------------------------------------------------------------- constants and envelope


def test_constants_and_kind_numbers_are_the_documented_ones():
    assert (MAGIC, WIRE_VERSION) == (b"LSHF", 2)
    assert (MAX_HEADER_BYTES, MAX_MESSAGE_BYTES, MAX_BATCH_ROWS) == (65536, 256 * 2**20, 65536)
    assert {k.name: int(k) for k in Kind} == {"TRANSITIONS": 1, "WEIGHTS": 2, "SAMPLE_REQUEST": 3, "BATCH": 4,
                                              "ERROR": 5, "JSON": 6, "PRIORITIES": 7}
    assert wire.ALLOWED_DTYPES == {"|u1", "|b1", "|i1", "<i2", "<u2", "<i4", "<u4", "<i8", "<f2", "<f4", "<f8"}


def test_envelope_layout_byte_by_byte():
    msg = encode(Kind.JSON, {"body": {"a": 1}}, {"x": np.array([1, 2], np.uint16)})
    magic, version, kind, reserved, hlen = struct.unpack_from("<4sHBBI", msg, 0)
    assert (magic, version, kind, reserved) == (b"LSHF", 2, 6, 0)
    header = json.loads(msg[12:12 + hlen])
    assert header == {"body": {"a": 1}, "arrays": [{"name": "x", "dtype": "<u2", "shape": [2]}]}
    assert msg[12 + hlen:] == b"\x01\x00\x02\x00"
    assert len(msg) == 12 + hlen + 4
    # compact JSON, no spaces
    assert b" " not in msg[12:12 + hlen]


def test_doc_hex_example_is_what_the_encoder_writes():
    """docs/wire.md carries a hex dump of a tiny TRANSITIONS message; it must stay exact."""
    text = DOC.read_text()
    block = text.split("<!-- hex-example -->", 1)[1].split("```", 2)[1]
    data = bytearray()
    for line in block.splitlines():
        m = re.match(r"^([0-9a-f]{8}):((?: [0-9a-f]{2}){1,16})", line)
        if m:
            assert int(m.group(1), 16) == len(data)
            data += bytes.fromhex(m.group(2))
    batch = TransitionBatch.from_arrays(
        actor="w0", seq=3, weights_version=7, phase=0, env_steps=128, obs=np.array([[0.5, -1.0]], np.float32),
        action=[4], reward=[1.0], next_obs=np.array([[0.25, 2.0]], np.float32), terminated=[0], truncated=[1])
    assert bytes(data) == encode_transitions(batch)
    decoded = decode_transitions(bytes(data), TransitionSchema((2,), "float32", 9))
    assert decoded.action.tolist() == [4] and decoded.truncated.tolist() == [1]


@pytest.mark.parametrize("code", sorted(wire.ALLOWED_DTYPES))
def test_every_allowed_dtype_round_trips(code):
    arr = (np.arange(12) % 2 if code == "|b1" else np.arange(12)).astype(code).reshape(3, 4)
    msg = decode(encode(Kind.JSON, {"body": {}}, {"a": arr}))
    assert msg.arrays["a"].dtype.str == code and np.array_equal(msg.arrays["a"], arr)


def test_big_endian_input_is_sent_little_endian():
    arr = np.arange(4, dtype=">f4")
    msg = encode(Kind.JSON, {"body": {}}, {"a": arr})
    assert b'"dtype":"<f4"' in msg and msg.endswith(np.arange(4, dtype="<f4").tobytes())
    assert np.array_equal(decode(msg).arrays["a"], arr)


def test_encoder_refuses_what_cannot_travel():
    for arr in (np.zeros(2, np.complex64), np.array(["a"]), np.zeros(2, object), np.zeros(2, np.uint64)):
        with pytest.raises(ValueError):
            encode(Kind.JSON, {"body": {}}, {"a": arr})
    with pytest.raises(ValueError):
        encode(Kind.JSON, {"body": {"x": float("nan")}})
    with pytest.raises(ValueError):
        encode(Kind.JSON, {"body": {"x": "y" * MAX_HEADER_BYTES}})


def test_decoded_arrays_are_copies_not_views_of_the_network_buffer():
    buf = bytearray(encode_transitions(make_batch()))
    batch = decode_transitions(buf, SCHEMA)
    before = batch.obs.copy()
    buf[-40:] = b"\xff" * 40
    assert np.array_equal(batch.obs, before) and batch.obs.flags.writeable


def test_peek_kind():
    assert peek_kind(encode_json({})) == Kind.JSON
    assert peek_kind(encode_error("x")) == Kind.ERROR
    assert peek_kind(b"LSHF") is None
    assert peek_kind(b"XXXX" + bytes(8)) is None
    assert peek_kind(envelope(kind=77)) is None


# --------------------------------------------------------------------------- round trips, every kind


@pytest.mark.parametrize("obs_shape,obs_dtype", [((3,), "float32"), ((4, 8, 8), "uint8"), ((5,), "float64")])
def test_transitions_round_trip(obs_shape, obs_dtype):
    schema = TransitionSchema(obs_shape, obs_dtype, n_actions=9)
    batch = TransitionBatch.from_arrays(actor="worker-1_a", seq=17, weights_version=4, phase=2, env_steps=12345,
                                        extra={"episode_ids": [1, 2, 2], "note": "x"}, **batch_arrays(3, obs_shape, obs_dtype))
    out = decode_transitions(encode_transitions(batch), schema)
    assert_same_batch(out, batch)
    assert len(out) == 3


def test_transitions_from_python_lists_and_bools():
    batch = TransitionBatch.from_arrays(actor="w0", seq=0, weights_version=0, phase=0, env_steps=2,
                                        obs=np.zeros((2, 3), np.float32), action=[1, 8], reward=[0.5, -1],
                                        next_obs=np.zeros((2, 3), np.float32), terminated=[False, True],
                                        truncated=[True, False])
    out = decode_transitions(encode_transitions(batch), SCHEMA)
    assert out.action.dtype == np.int64 and out.terminated.dtype == np.uint8
    assert out.terminated.tolist() == [0, 1] and out.truncated.tolist() == [1, 0]


def test_max_rows_is_accepted():
    schema = TransitionSchema((1,), "float32", 9, max_rows=5)
    a = batch_arrays(5, (1,))
    out = decode_transitions(encode_transitions(make_batch(5, **a)), schema)
    assert len(out) == 5


def test_weights_round_trip():
    tensors = {"net.0.weight": np.random.default_rng(0).normal(size=(4, 3)).astype(np.float32),
               "net.0.bias": np.zeros(4, np.float32), "steps": np.array([7], np.int64)}
    w = decode_weights(encode_weights(Weights(version=3, phase=2, updates=150, tensors=tensors)))
    assert (w.version, w.phase, w.updates) == (3, 2, 150)
    assert set(w.tensors) == set(tensors)
    for k, v in tensors.items():
        assert w.tensors[k].dtype == v.dtype and np.array_equal(w.tensors[k], v)


def test_weights_message_carries_one_uint8_safetensors_array_with_version_metadata():
    msg = decode(encode_weights(Weights(1, 0, 0, {"a": np.ones(2, np.float32)})), expect=Kind.WEIGHTS)
    assert msg.header == {"version": 1, "phase": 0, "updates": 0}
    assert list(msg.arrays) == ["safetensors"] and msg.arrays["safetensors"].dtype.str == "|u1"
    tensors, meta = safetensors_loads(msg.arrays["safetensors"].tobytes())
    assert meta == {"version": "1"} and np.array_equal(tensors["a"], np.ones(2, np.float32))


@pytest.mark.parametrize("req", [SampleRequest(256), SampleRequest(64, 8, min_version=5, actors=("w0", "w1")),
                                 SampleRequest(1, 64), SampleRequest(MAX_BATCH_ROWS, 1),
                                 SampleRequest(32, 4, next_obs=False)])
def test_sample_request_round_trip(req):
    assert decode_sample_request(encode_sample_request(req)) == req


def test_sample_request_header_fields():
    msg = decode(encode_sample_request(SampleRequest(32, 2, 3, ("w0",))))
    assert msg.header == {"batch_size": 32, "num_batches": 2, "min_version": 3, "actors": ["w0"], "next_obs": True}
    assert msg.arrays == {}


def test_sample_request_actors_and_next_obs_fields_are_optional():
    req = decode_sample_request(envelope(3, {"batch_size": 4, "num_batches": 1, "min_version": -1, "arrays": []}))
    assert req == SampleRequest(4) and req.next_obs is True


def test_a_batch_without_next_obs_round_trips_and_nothing_else_may_be_missing():
    """The reply to SampleRequest(next_obs=False): every field but next_obs, decoded with next_obs None."""
    b = dataclasses.replace(_sampled(), next_obs=None)
    data = encode_batch(b)
    assert "next_obs" not in decode(data).arrays and len(data) < len(encode_batch(_sampled()))
    out = decode_batch(data, SCHEMA)
    assert out.next_obs is None and out.num_batches == 2 and out.info == {"phase": 1}
    for f in BATCH_FIELDS:
        if f != "next_obs":
            assert np.array_equal(getattr(out, f), getattr(b, f)) and getattr(out, f).dtype == getattr(b, f).dtype
    arrays = {f: getattr(b, f) for f in BATCH_FIELDS if f != "next_obs"}
    for missing in ("obs", "weight"):
        partial = {k: v for k, v in arrays.items() if k != missing}
        assert reason_of(decode_batch, encode(Kind.BATCH, {"num_batches": 1}, partial), SCHEMA) == "bad_arrays"


def _sampled(rows: int = 4, nb: int = 2) -> SampledBatch:
    a = batch_arrays(rows)
    return SampledBatch(obs=a["obs"], action=a["action"], reward=a["reward"], next_obs=a["next_obs"],
                        terminated=a["terminated"], steps=a["steps"], is_demo=np.array([1, 0, 0, 1][:rows], np.uint8),
                        index=np.arange(rows, dtype=np.int64) * 10, weight=np.ones(rows, np.float32),
                        num_batches=nb, info={"phase": 1})


def test_batch_round_trip():
    b = _sampled()
    out = decode_batch(encode_batch(b), SCHEMA)
    assert out.num_batches == 2 and out.info == {"phase": 1}
    for f in BATCH_FIELDS:
        assert np.array_equal(getattr(out, f), getattr(b, f)) and getattr(out, f).dtype == getattr(b, f).dtype


def test_json_round_trip():
    body = {"cmd": "set_phase", "phase": 2, "nested": {"a": [1, 2.5, None, True, "x"]}}
    assert decode_json(encode_json(body)) == body
    assert decode(encode_json(body)).header == {"body": body}


def test_error_round_trip():
    err = decode_error(encode_error("rate_limited", "online size 3", retry_after_ms=5))
    assert isinstance(err, WireError) and (err.reason, err.detail, err.retry_after_ms) == ("rate_limited",
                                                                                          "online size 3", 5)
    assert decode(encode_error("x")).header == {"reason": "x", "detail": "", "retry_after_ms": 0}
    assert decode_error(envelope(5, {"arrays": []})).reason == "error"


def test_wire_error_is_a_value_error_with_reason_and_detail():
    e = WireError("bad_magic", "detail here")
    assert isinstance(e, ValueError) and e.reason == "bad_magic" and e.detail == "detail here"
    assert str(e) == "bad_magic: detail here"


# --------------------------------------------------------------------------- envelope validation


def test_wrong_magic():
    msg = bytearray(encode_transitions(make_batch()))
    msg[0:4] = b"LSHG"
    assert reason_of(decode_transitions, bytes(msg), SCHEMA) == "bad_magic"


def test_wrong_version():
    assert reason_of(decode, envelope(6, {"body": {}, "arrays": []}, version=1)) == "wrong_version"
    assert reason_of(decode, envelope(6, {"body": {}, "arrays": []}, version=3)) == "wrong_version"
    assert reason_of(decode, envelope(6, {"body": {}, "arrays": []}, version=0)) == "wrong_version"


def test_unknown_kind_and_wrong_kind():
    assert reason_of(decode, envelope(0, {"arrays": []})) == "bad_kind"
    assert reason_of(decode, envelope(8, {"arrays": []})) == "bad_kind"
    assert reason_of(decode_transitions, encode_json({}), SCHEMA) == "wrong_kind"
    assert reason_of(decode_weights, encode_json({})) == "wrong_kind"
    assert reason_of(decode_sample_request, encode_json({})) == "wrong_kind"
    assert reason_of(decode_batch, encode_json({}), SCHEMA) == "wrong_kind"
    assert reason_of(decode_json, encode_error("x")) == "wrong_kind"
    assert reason_of(decode_error, encode_json({})) == "wrong_kind"


def test_reserved_byte_must_be_zero():
    msg = bytearray(encode_transitions(make_batch()))
    msg[7] = 1
    assert reason_of(decode_transitions, bytes(msg), SCHEMA) == "bad_envelope"


@pytest.mark.parametrize("hlen", [0, 1, MAX_HEADER_BYTES + 1, 2**32 - 1])
def test_header_length_out_of_range(hlen):
    assert reason_of(decode, envelope(6, b"{}", hlen=hlen)) == "bad_header"


def test_header_longer_than_message_is_truncated():
    assert reason_of(decode, envelope(6, b'{"arrays":[]}', hlen=100)) == "truncated"


@pytest.mark.parametrize("n", range(12))
def test_shorter_than_envelope_is_truncated(n):
    assert reason_of(decode, encode_json({})[:n]) == "truncated"


@pytest.mark.parametrize("head", [b"\xff\xfe{}", b"not json", b'{"arrays":[]', b"{'arrays':[]}", b"[1,2]",
                                  b'"x"', b"{}", b'{"arrays":{}}', b'{"arrays":null}'])
def test_non_json_or_malformed_header(head):
    assert reason_of(decode, envelope(6, head)) == "bad_header"


@pytest.mark.parametrize("const", ["NaN", "Infinity", "-Infinity"])
def test_nan_and_infinity_in_header_refused(const):
    head = ('{"body":{"x":%s},"arrays":[]}' % const).encode()
    assert reason_of(decode, envelope(6, head)) == "bad_header"
    head = ('{"actor":"w0","seq":%s,"arrays":[]}' % const).encode()
    assert reason_of(decode_transitions, envelope(1, head), SCHEMA) == "bad_header"


def test_header_number_overflowing_to_infinity_refused():
    """``1e999`` parses to ``inf``: it is refused like the NaN/Infinity literals, which the encoder
    (``allow_nan=False``) can never write either. Let through, a ``float('inf')`` in a JSON body would
    reach e.g. the learner's episode statistics (``float(ep["return"])``)."""
    head = b'{"body":{"return":1e999},"arrays":[]}'
    assert reason_of(decode, envelope(6, head)) == "bad_header"


@pytest.mark.parametrize("code", [">f4", "<c8", "|O", "float32", "<u8", "<M8[s]", "", 4])
def test_unknown_dtype(code):
    head = {"body": {}, "arrays": [{"name": "a", "dtype": code, "shape": [1]}]}
    assert reason_of(decode, envelope(6, head, b"\0" * 16)) == "bad_dtype"


@pytest.mark.parametrize("code", [[], {}, ["<f4"]])
def test_unhashable_dtype_is_a_wire_error(code):
    """A JSON list or object as an array's dtype is WireError("bad_dtype"), not the
    ``TypeError: unhashable type`` that looking it up in ``ALLOWED_DTYPES`` would raise."""
    head = {"body": {}, "arrays": [{"name": "a", "dtype": code, "shape": [1]}]}
    assert reason_of(decode, envelope(6, head, b"\0")) == "bad_dtype"


@pytest.mark.parametrize("shape", [[-1], [1.0], [True], ["2"], [2**31], [1] * 9, "1", 3, None, [[1]]])
def test_bad_shape(shape):
    head = {"body": {}, "arrays": [{"name": "a", "dtype": "|u1", "shape": shape}]}
    assert reason_of(decode, envelope(6, head, b"\0")) == "bad_shape"


def test_shape_limits_accepted():
    head = {"body": {}, "arrays": [{"name": "a", "dtype": "|u1", "shape": [1] * 8},
                                   {"name": "b", "dtype": "|u1", "shape": [0, 2**31 - 1]},
                                   {"name": "c", "dtype": "<f4", "shape": []}]}
    msg = decode(envelope(6, head, b"\x07" + b"\0\0\x80\x3f"))
    assert msg.arrays["a"].shape == (1,) * 8 and msg.arrays["b"].shape == (0, 2**31 - 1)
    assert msg.arrays["c"].shape == () and float(msg.arrays["c"]) == 1.0


@pytest.mark.parametrize("entry", [{"name": "a", "dtype": "|u1"}, {"name": "a", "dtype": "|u1", "shape": [1], "x": 1},
                                   ["a", "|u1", [1]], "a", None,
                                   {"name": "a/b", "dtype": "|u1", "shape": [1]},
                                   {"name": "", "dtype": "|u1", "shape": [1]},
                                   {"name": "x" * 65, "dtype": "|u1", "shape": [1]},
                                   {"name": 5, "dtype": "|u1", "shape": [1]}])
def test_bad_array_entry(entry):
    assert reason_of(decode, envelope(6, {"body": {}, "arrays": [entry]}, b"\0")) == "bad_header"


def test_truncated_arrays():
    msg = encode_transitions(make_batch())
    for cut in (1, 2, 9, 30):
        assert reason_of(decode_transitions, msg[:-cut], SCHEMA) == "truncated"
    head = {"body": {}, "arrays": [{"name": "a", "dtype": "<f8", "shape": [2**31 - 1] * 8}]}
    assert reason_of(decode, envelope(6, head, b"\0" * 8)) == "truncated"


def test_trailing_bytes():
    msg = encode_transitions(make_batch())
    assert reason_of(decode_transitions, msg + b"\0", SCHEMA) == "trailing_bytes"
    assert reason_of(decode, encode_json({}) + b"x") == "trailing_bytes"


def test_oversized(monkeypatch):
    msg = encode_transitions(make_batch())
    monkeypatch.setattr(envelope_module, "MAX_MESSAGE_BYTES", len(msg) - 1)
    assert reason_of(decode_transitions, msg, SCHEMA) == "oversized"
    monkeypatch.setattr(envelope_module, "MAX_MESSAGE_BYTES", len(msg))
    decode_transitions(msg, SCHEMA)


def test_oversized_checked_before_anything_else(monkeypatch):
    monkeypatch.setattr(envelope_module, "MAX_MESSAGE_BYTES", 4)
    assert reason_of(decode, b"garbage") == "oversized"


def test_duplicate_array_names():
    spec = {"name": "a", "dtype": "|u1", "shape": [1]}
    assert reason_of(decode, envelope(6, {"body": {}, "arrays": [spec, spec]}, b"\1\2")) == "bad_header"
    h = json.loads(tmsg()[12:12 + struct.unpack_from("<I", tmsg(), 8)[0]])
    h["arrays"].append(h["arrays"][1])  # "action" twice
    body = tmsg()[12 + struct.unpack_from("<I", tmsg(), 8)[0]:]
    assert reason_of(decode_transitions, envelope(1, h, body + b"\0" * 16), SCHEMA) == "bad_header"


def test_deeply_nested_header_is_a_wire_error():
    """json.loads raises RecursionError (not ValueError) on ~1000 nested brackets, which fit easily
    in a 64 KiB header; every decoder turns it into WireError("bad_header"). The learner and the env
    workers catch only WireError around ``decode_json`` of the ``control``/``replay/flow`` keys, so
    anything else escaping would let one such message published there kill them."""
    deep = b'{"body":' + b"[" * 5000 + b"]" * 5000 + b',"arrays":[]}'
    assert reason_of(decode_json, envelope(6, deep)) == "bad_header"
    deep_t = b'{"actor":"w0","extra":' + b"[" * 5000 + b"]" * 5000 + b',"arrays":[]}'
    assert reason_of(decode_transitions, envelope(1, deep_t), SCHEMA) == "bad_header"


# --------------------------------------------------------------------------- transitions schema


@pytest.mark.parametrize("header", [{"actor": None}, {"actor": 5}, {"actor": ""}, {"actor": "a/b"}, {"actor": "w 0"},
                                    {"actor": "x" * 65}, {"actor": "wü"}, {"seq": -1}, {"seq": 1.0}, {"seq": True},
                                    {"seq": "1"}, {"weights_version": -1}, {"phase": None}, {"env_steps": -5},
                                    {"extra": []}, {"extra": "x"}])
def test_bad_transition_header_fields(header):
    assert reason_of(decode_transitions, tmsg(header), SCHEMA) == "bad_header"


@pytest.mark.parametrize("field", ["actor", "seq", "weights_version", "phase", "env_steps"])
def test_missing_transition_header_field(field):
    assert reason_of(decode_transitions, tmsg(drop=(field,)), SCHEMA) == "bad_header"


def test_extra_is_optional():
    out = decode_transitions(tmsg(drop=("extra",)), SCHEMA)
    assert out.extra == {}


@pytest.mark.parametrize("name", ["obs", "action", "reward", "next_obs", "terminated", "truncated", "steps"])
def test_missing_array(name):
    assert reason_of(decode_transitions, tmsg(drop=(name,)), SCHEMA) == "bad_arrays"


def test_unexpected_array():
    assert reason_of(decode_transitions, tmsg(arrays={"priority": np.ones(2, np.float32)}), SCHEMA) == "bad_arrays"


def test_row_count_limits():
    assert reason_of(decode_transitions, tmsg(arrays=batch_arrays(0)), SCHEMA) == "bad_shape"
    small = TransitionSchema((3,), "float32", 9, max_rows=4)
    assert reason_of(decode_transitions, tmsg(arrays=batch_arrays(5)), small) == "bad_shape"
    assert reason_of(decode_transitions, tmsg(arrays={"action": np.zeros((2, 1), np.int64)}), SCHEMA) == "bad_shape"


@pytest.mark.parametrize("arrays", [{"obs": np.zeros((2, 4), np.float32)}, {"next_obs": np.zeros((2, 3, 1), np.float32)},
                                    {"obs": np.zeros((3, 3), np.float32)}, {"reward": np.zeros(3, np.float32)},
                                    {"terminated": np.zeros(1, np.uint8)}, {"truncated": np.zeros((2, 1), np.uint8)},
                                    {"steps": np.ones(3, np.uint8)}])
def test_wrong_shapes(arrays):
    assert reason_of(decode_transitions, tmsg(arrays=arrays), SCHEMA) == "bad_shape"


@pytest.mark.parametrize("arrays", [{"obs": np.zeros((2, 3), np.float64)}, {"next_obs": np.zeros((2, 3), np.uint8)},
                                    {"action": np.zeros(2, np.int32)}, {"action": np.zeros(2, np.uint8)},
                                    {"reward": np.zeros(2, np.float64)}, {"terminated": np.zeros(2, np.bool_)},
                                    {"truncated": np.zeros(2, np.int64)}, {"steps": np.ones(2, np.int64)}])
def test_wrong_dtypes(arrays):
    assert reason_of(decode_transitions, tmsg(arrays=arrays), SCHEMA) == "bad_dtype"


def test_uint8_observation_schema_refuses_float_obs():
    schema = TransitionSchema((4, 8, 8), "uint8", 9)
    assert reason_of(decode_transitions, tmsg(), schema) == "bad_shape"
    ok = encode_transitions(make_batch(2, **batch_arrays(2, (4, 8, 8), "uint8")))
    decode_transitions(ok, schema)
    bad = encode_transitions(make_batch(2, **batch_arrays(2, (4, 8, 8), "float32")))
    assert reason_of(decode_transitions, bad, schema) == "bad_dtype"


@pytest.mark.parametrize("action", [[-1, 0], [0, 9], [0, 2**40]])
def test_action_out_of_range(action):
    assert reason_of(decode_transitions, tmsg(arrays={"action": np.array(action, np.int64)}), SCHEMA) == "bad_value"


def test_action_edges_accepted():
    out = decode_transitions(tmsg(arrays={"action": np.array([0, 8], np.int64)}), SCHEMA)
    assert out.action.tolist() == [0, 8]


@pytest.mark.parametrize("name,values", [("terminated", [0, 2]), ("terminated", [255, 0]), ("truncated", [1, 2])])
def test_terminated_truncated_must_be_0_or_1(name, values):
    assert reason_of(decode_transitions, tmsg(arrays={name: np.array(values, np.uint8)}), SCHEMA) == "bad_value"


def test_steps_must_be_at_least_1():
    assert reason_of(decode_transitions, tmsg(arrays={"steps": np.array([1, 0], np.uint8)}), SCHEMA) == "bad_value"
    assert decode_transitions(tmsg(arrays={"steps": np.array([1, 255], np.uint8)}), SCHEMA).steps.tolist() == [1, 255]


def test_steps_default_to_one_step_transitions():
    fields = batch_arrays(3)
    del fields["steps"]
    b = TransitionBatch.from_arrays(actor="w0", seq=0, weights_version=0, phase=0, env_steps=3, **fields)
    assert b.steps.tolist() == [1, 1, 1] and b.steps.dtype == np.uint8


@pytest.mark.parametrize("name", ["obs", "next_obs", "reward"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_values(name, bad):
    arr = batch_arrays(2)[name].copy()
    arr.flat[-1] = bad
    assert reason_of(decode_transitions, tmsg(arrays={name: arr}), SCHEMA) == "non_finite"


def test_validation_order_is_stable():
    # Several problems at once: the first failing rule names the reason.
    both = tmsg({"actor": "a/b"}, {"action": np.array([99, 99], np.int64)})
    assert reason_of(decode_transitions, both, SCHEMA) == "bad_header"
    shape_and_value = tmsg(arrays={"obs": np.zeros((2, 4), np.float32), "action": np.array([99, 99], np.int64)})
    assert reason_of(decode_transitions, shape_and_value, SCHEMA) == "bad_shape"


# --------------------------------------------------------------------------- names and key expressions

KEY_BUILDERS_RUN = [wire.transitions_wildcard, wire.weights_key, wire.weights_latest_key, wire.sample_key,
                    wire.replay_stats_key, wire.replay_control_key, wire.replay_flow_key, wire.episodes_wildcard,
                    wire.learner_stats_key, wire.control_key]
BAD_NAMES = ["", "a/b", "a b", "*", "**", "$*", "a?", "x" * 65, "wü", "a.b", None, 5]


def test_key_expressions_exact():
    assert wire.transitions_key("r1", "w0") == "laneshift/r1/transitions/w0"
    assert wire.transitions_wildcard("r1") == "laneshift/r1/transitions/*"
    assert wire.weights_key("r1") == "laneshift/r1/weights"
    assert wire.weights_latest_key("r1") == "laneshift/r1/weights/latest"
    assert wire.sample_key("r1") == "laneshift/r1/replay/sample"
    assert wire.replay_stats_key("r1") == "laneshift/r1/replay/stats"
    assert wire.replay_control_key("r1") == "laneshift/r1/replay/control"
    assert wire.replay_flow_key("r1") == "laneshift/r1/replay/flow"
    assert wire.episodes_key("r1", "w3") == "laneshift/r1/episodes/w3"
    assert wire.episodes_wildcard("r1") == "laneshift/r1/episodes/*"
    assert wire.learner_stats_key("r1") == "laneshift/r1/learner/stats"
    assert wire.control_key("r1") == "laneshift/r1/control"
    assert wire.actor_from_transitions_key("laneshift/r1/transitions/w_7-x") == "w_7-x"


@pytest.mark.parametrize("name", ["a", "A-b_9", "x" * 64, "-", "_"])
def test_good_names_accepted(name):
    assert wire.transitions_key(name, name).endswith("/" + name)
    for build in KEY_BUILDERS_RUN:
        assert build(name).startswith(f"laneshift/{name}/")


@pytest.mark.parametrize("bad", BAD_NAMES)
def test_key_builders_reject_bad_names(bad):
    for build in KEY_BUILDERS_RUN:
        with pytest.raises(ValueError):
            build(bad)
    with pytest.raises(ValueError):
        wire.transitions_key("run", bad)
    with pytest.raises(ValueError):
        wire.transitions_key(bad, "w0")
    with pytest.raises(ValueError):
        wire.episodes_key("run", bad)
    if isinstance(bad, str) and "/" not in bad:  # the actor is the key's last chunk
        with pytest.raises(ValueError):
            wire.actor_from_transitions_key("laneshift/run/transitions/" + bad)


def test_names_with_a_trailing_newline_are_refused():
    """Names are matched whole (``_NAME.fullmatch``): a pattern ending in ``$`` applied with
    ``.match`` would also match before a final newline and let "w0\\n" pass every name check (key
    builders, the actor in transitions headers, sample-request actor lists, array names and
    ``TransportConfig.run_id``)."""
    with pytest.raises(ValueError):
        wire.transitions_key("run", "w0\n")
    with pytest.raises(ValueError):
        wire.control_key("run\n")
    assert reason_of(decode_transitions, tmsg({"actor": "w0\n"}), SCHEMA) == "bad_header"
    req = envelope(3, {"batch_size": 4, "num_batches": 1, "min_version": 0, "actors": ["w0\n"], "arrays": []})
    assert reason_of(decode_sample_request, req) == "bad_request"


# --------------------------------------------------------------------------- weights validation


def _weights_msg(header: dict | None = None, arrays: dict | None = None) -> bytes:
    blob = safetensors_dumps({"a": np.ones(2, np.float32)})
    h = {"version": 1, "phase": 0, "updates": 0, **(header or {})}
    return encode(Kind.WEIGHTS, h, arrays if arrays is not None else {"safetensors": np.frombuffer(blob, np.uint8)})


@pytest.mark.parametrize("header", [{"version": -1}, {"version": "1"}, {"version": 1.5}, {"phase": None},
                                    {"updates": True}, {"version": None}])
def test_bad_weights_header(header):
    assert reason_of(decode_weights, _weights_msg(header)) == "bad_header"


def test_weights_arrays_rules():
    blob = np.frombuffer(safetensors_dumps({"a": np.ones(2, np.float32)}), np.uint8)
    assert reason_of(decode_weights, _weights_msg(arrays={})) == "bad_arrays"
    assert reason_of(decode_weights, _weights_msg(arrays={"safetensors": blob, "x": blob})) == "bad_arrays"
    assert reason_of(decode_weights, _weights_msg(arrays={"blob": blob})) == "bad_arrays"
    two_d = blob[: len(blob) // 8 * 8].reshape(-1, 8)
    assert reason_of(decode_weights, _weights_msg(arrays={"safetensors": two_d})) == "bad_arrays"
    assert reason_of(decode_weights, _weights_msg(arrays={"safetensors": blob[:-1]})) == "bad_weights"


def test_weights_blob_must_be_uint8():
    """The contract says exactly one 1-D ``|u1`` array: ``decode_weights`` checks the blob's dtype
    too (reason bad_arrays), so a float32 array whose bytes happen to form a safetensors file is
    refused."""
    blob = safetensors_dumps({"a": np.ones(2, np.float32)})
    assert len(blob) % 4 == 0
    as_f32 = np.frombuffer(blob, np.float32)
    assert reason_of(decode_weights, _weights_msg(arrays={"safetensors": as_f32})) == "bad_arrays"


def test_non_finite_weights_refused():
    blob = np.frombuffer(safetensors_dumps({"a": np.array([1.0, np.nan], np.float32)}), np.uint8)
    assert reason_of(decode_weights, _weights_msg(arrays={"safetensors": blob})) == "non_finite"


# --------------------------------------------------------------------------- safetensors


TENSORS = {"w": np.arange(6, dtype=np.float32).reshape(2, 3), "b": np.array([1, -2], np.int64),
           "m": np.array([True, False]), "e": np.zeros((0, 4), np.float16), "u": np.array([1, 255], np.uint8),
           "i8": np.array([-1], np.int8), "i16": np.array([3], np.int16), "i32": np.array([3], np.int32),
           "d": np.array([1.5])}


def _assert_tensors_equal(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and np.array_equal(a[k], b[k]), k


def test_our_blob_is_read_by_the_safetensors_package():
    _assert_tensors_equal(stn.load(safetensors_dumps(TENSORS, {"k": "v"})), TENSORS)


def test_the_safetensors_package_blob_is_read_by_us():
    tensors, meta = safetensors_loads(stn.save(TENSORS, metadata={"version": "9", "x": "y"}))
    _assert_tensors_equal(tensors, TENSORS)
    assert meta == {"version": "9", "x": "y"}


def test_safetensors_file_interop(tmp_path):
    path = tmp_path / "t.safetensors"
    stn.save_file(TENSORS, str(path))
    _assert_tensors_equal(safetensors_loads(path.read_bytes())[0], TENSORS)
    path.write_bytes(safetensors_dumps(TENSORS))
    _assert_tensors_equal(stn.load_file(str(path)), TENSORS)


def test_safetensors_layout():
    blob = safetensors_dumps({"b": np.array([1], np.uint8), "a": np.array([2.0], np.float32)}, {"version": "3"})
    (hlen,) = struct.unpack_from("<Q", blob, 0)
    assert hlen % 8 == 0
    header = json.loads(blob[8:8 + hlen])
    assert header == {"__metadata__": {"version": "3"},
                      "a": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]},
                      "b": {"dtype": "U8", "shape": [1], "data_offsets": [4, 5]}}
    assert blob[8 + hlen:] == np.array([2.0], np.float32).tobytes() + b"\x01"
    assert safetensors_loads(safetensors_dumps({})) == ({}, {})


def test_safetensors_zero_dim_tensor_keeps_its_shape():
    """A 0-d tensor keeps shape ``()`` (``np.ascontiguousarray`` alone returns ndim >= 1, which would
    write it with shape [1]). A torch state dict with a 0-d entry (e.g. BatchNorm's
    ``num_batches_tracked``) would otherwise fail ``load_into``'s strict shape check on every env
    worker."""
    t = {"scalar": np.array(2.0, np.float32)}
    assert stn.load(safetensors_dumps(t))["scalar"].shape == ()
    assert safetensors_loads(safetensors_dumps(t))[0]["scalar"].shape == ()
    assert safetensors_loads(stn.save(t))[0]["scalar"].shape == ()


def test_safetensors_unsigned_16_and_32_bit():
    """``<u2``/``<u4``, allowed on the wire, are written and read as safetensors U16/U32, which the
    format and the safetensors package support (both directions checked against the package)."""
    t = {"a": np.array([1, 2], np.uint16), "b": np.array([3], np.uint32)}
    _assert_tensors_equal(stn.load(safetensors_dumps(t)), t)
    _assert_tensors_equal(safetensors_loads(stn.save(t))[0], t)


def _st(header: dict | bytes, data: bytes = b"", hlen: int | None = None) -> bytes:
    head = header if isinstance(header, bytes) else json.dumps(header).encode()
    return struct.pack("<Q", len(head) if hlen is None else hlen) + head + data


@pytest.mark.parametrize("blob", [
    b"", b"\0" * 7,
    _st({}, hlen=100),  # header length past the end
    _st({}, hlen=2**63),
    _st(b"\xff\xfe"), _st(b"{not json"), _st(b"[1, 2]"), _st(b'"x"'),
    _st({"a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]}}, b"\0" * 4),  # out of range
    _st({"a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 4]}}, b"\0" * 8),  # size != shape
    _st({"a": {"dtype": "F32", "shape": [1], "data_offsets": [4, 0]}}, b"\0" * 8),  # reversed
    _st({"a": {"dtype": "F32", "shape": [1], "data_offsets": [-4, 0]}}, b"\0" * 8),
    _st({"a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]},
         "b": {"dtype": "F32", "shape": [2], "data_offsets": [4, 12]}}, b"\0" * 12),  # overlap
    _st({"a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]},
         "b": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]}}, b"\0" * 8),  # same span twice
    _st({"a": {"dtype": "F8_E4M3", "shape": [1], "data_offsets": [0, 1]}}, b"\0"),
    _st({"a": {"dtype": "C64", "shape": [1], "data_offsets": [0, 8]}}, b"\0" * 8),
    _st({"a": {"dtype": "F32", "shape": [-1, -1], "data_offsets": [0, 4]}}, b"\0" * 4),
    _st({"a": {"dtype": "F32", "shape": [1]}}, b"\0" * 4),
    _st({"a": {"shape": [1], "data_offsets": [0, 4]}}, b"\0" * 4),
    _st({"a": {"dtype": "F32", "shape": [1], "data_offsets": [0]}}, b"\0" * 4),
    _st({"a": {"dtype": "F32", "shape": None, "data_offsets": [0, 4]}}, b"\0" * 4),
    _st({"a": [1, 2]}, b""), _st({"a": "F32"}, b""), _st({"a": None}, b""),
    _st({"a": {"dtype": ["F32"], "shape": [1], "data_offsets": [0, 4]}}, b"\0" * 4),
])
def test_corrupt_safetensors_refused(blob):
    assert reason_of(safetensors_loads, blob) == "bad_weights"


@pytest.mark.parametrize("meta", [[1, 2], "ab", 5, [["a"]]])
def test_safetensors_bad_metadata_is_a_wire_error(meta):
    """A ``__metadata__`` that is a list, string or number is WireError("bad_weights"), not the
    TypeError/ValueError of ``dict(meta)``."""
    assert reason_of(safetensors_loads, _st({"__metadata__": meta})) == "bad_weights"


@pytest.mark.parametrize("head", [b"[" * 5000, b'{"a":' + b"9" * 5000 + b"}"])
def test_safetensors_pathological_header_is_a_wire_error(head):
    """Deep nesting (RecursionError) and a >4300-digit integer (a plain ValueError) in a safetensors
    header are WireError("bad_weights") too, like undecodable or malformed JSON."""
    assert reason_of(safetensors_loads, _st(head)) == "bad_weights"


def test_corrupt_blob_inside_weights_message():
    for blob in (b"\0" * 8, _st({"a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 9]}}, b"\0" * 8)):
        msg = encode(Kind.WEIGHTS, {"version": 1, "phase": 0, "updates": 0}, {"safetensors": np.frombuffer(blob, np.uint8)})
        assert reason_of(decode_weights, msg) == "bad_weights"


# --------------------------------------------------------------------------- sample requests, batches, json


@pytest.mark.parametrize("kw", [{"batch_size": 0}, {"batch_size": MAX_BATCH_ROWS + 1}, {"batch_size": 8, "num_batches": 0},
                                {"batch_size": 8, "num_batches": 65}, {"batch_size": 2048, "num_batches": 64}])
def test_sample_request_ranges(kw):
    with pytest.raises(WireError) as info:
        SampleRequest(**kw)
    assert info.value.reason == "bad_request"
    head = {"batch_size": 1, "num_batches": 1, "min_version": -1, "actors": [], **kw, "arrays": []}
    assert reason_of(decode_sample_request, envelope(3, head)) == "bad_request"


@pytest.mark.parametrize("patch", [{"batch_size": None}, {"batch_size": "8"}, {"batch_size": True},
                                   {"num_batches": 1.0}, {"min_version": None}, {"actors": "w0"},
                                   {"actors": ["w0", 1]}, {"actors": ["a/b"]}, {"actors": None},
                                   {"next_obs": 0}, {"next_obs": "false"}, {"next_obs": None}])
def test_sample_request_bad_fields(patch):
    head = {"batch_size": 8, "num_batches": 1, "min_version": -1, "actors": [], **patch, "arrays": []}
    assert reason_of(decode_sample_request, envelope(3, head)) == "bad_request"


def test_batch_validation():
    good = _sampled()
    arrays = {f: getattr(good, f) for f in BATCH_FIELDS}
    msg = lambda header, arrs: encode(Kind.BATCH, header, arrs)  # noqa: E731
    assert reason_of(decode_batch, msg({"num_batches": 1}, {k: v for k, v in arrays.items() if k != "weight"}),
                     SCHEMA) == "bad_arrays"
    assert reason_of(decode_batch, msg({"num_batches": 1}, {**arrays, "obs": np.zeros((4, 2), np.float32)}),
                     SCHEMA) == "bad_shape"
    assert reason_of(decode_batch, msg({"num_batches": 1}, {**arrays, "obs": arrays["obs"].astype(np.float64)}),
                     SCHEMA) == "bad_shape"
    assert reason_of(decode_batch, msg({"num_batches": 1}, {**arrays, "index": np.zeros(3, np.int64)}),
                     SCHEMA) == "bad_shape"
    assert reason_of(decode_batch, msg({"num_batches": 3}, arrays), SCHEMA) == "bad_header"
    assert reason_of(decode_batch, msg({"num_batches": 0}, arrays), SCHEMA) == "bad_header"
    assert reason_of(decode_batch, msg({}, arrays), SCHEMA) == "bad_header"
    assert decode_batch(msg({"num_batches": 4}, arrays), SCHEMA).info == {}


def test_batch_with_scalar_action_is_a_wire_error():
    """An ``action`` of shape ``[]`` is WireError("bad_shape"): ``decode_batch`` checks
    ``action.ndim == 1`` before it reads the row count from it (an IndexError there would escape
    the learner's ``ReplayClient.sample``, which catches only WireError)."""
    specs = [{"name": n, "dtype": "<i8", "shape": []} for n in BATCH_FIELDS]
    assert reason_of(decode_batch, envelope(4, {"num_batches": 1, "arrays": specs}, b"\0" * 8 * len(specs)), SCHEMA) == "bad_shape"


def test_json_validation():
    assert reason_of(decode_json, encode(Kind.JSON, {"body": {}}, {"a": np.zeros(1, np.uint8)})) == "bad_header"
    assert reason_of(decode_json, encode(Kind.JSON, {"body": [1]})) == "bad_header"
    assert reason_of(decode_json, encode(Kind.JSON, {})) == "bad_header"


def test_error_with_malformed_retry_after_is_a_wire_error():
    """A ``retry_after_ms`` that is not an integer ("soon", a list) is a WireError, not the
    ValueError/TypeError of ``int(...)``: the learner reads ERROR replies through
    ``transport.query_ok``, which handles only WireError."""
    for bad in ("soon", [1]):
        with pytest.raises(WireError):
            decode_error(envelope(5, {"reason": "x", "detail": "", "retry_after_ms": bad, "arrays": []}))


# --------------------------------------------------------------------------- property tests


@st.composite
def valid_batches(draw) -> tuple[TransitionBatch, TransitionSchema]:
    obs_shape = tuple(draw(st.lists(st.integers(1, 3), min_size=1, max_size=3)))
    obs_dtype = draw(st.sampled_from(["float32", "uint8", "float64"]))
    n_actions = draw(st.integers(1, 9))
    rows = draw(st.integers(1, 4))
    size = rows * math.prod(obs_shape)
    if obs_dtype == "uint8":
        elem = st.integers(0, 255)
    else:
        elem = st.floats(-1e6, 1e6, allow_nan=False, width=32)
    obs = np.array(draw(st.lists(elem, min_size=size, max_size=size)), obs_dtype).reshape(rows, *obs_shape)
    nxt = np.array(draw(st.lists(elem, min_size=size, max_size=size)), obs_dtype).reshape(rows, *obs_shape)
    batch = TransitionBatch.from_arrays(
        actor=draw(st.from_regex(r"\A[A-Za-z0-9_\-]{1,12}\Z")), seq=draw(st.integers(0, 2**40)),
        weights_version=draw(st.integers(0, 2**31 - 1)), phase=draw(st.integers(0, 2)),
        env_steps=draw(st.integers(0, 2**40)),
        extra=draw(st.dictionaries(st.text(max_size=4), st.integers() | st.text(max_size=4), max_size=2)),
        obs=obs, next_obs=nxt,
        action=draw(st.lists(st.integers(0, n_actions - 1), min_size=rows, max_size=rows)),
        reward=draw(st.lists(st.floats(-1e3, 1e3, allow_nan=False, width=32), min_size=rows, max_size=rows)),
        terminated=draw(st.lists(st.integers(0, 1), min_size=rows, max_size=rows)),
        truncated=draw(st.lists(st.integers(0, 1), min_size=rows, max_size=rows)))
    return batch, TransitionSchema(obs_shape, obs_dtype, n_actions)


REGION = st.sampled_from(["arrays", "header", "end", "arrays", "header", "envelope"])
MUTATION = st.one_of(
    st.tuples(st.just("flip"), REGION, st.integers(0, 10**6), st.integers(0, 7)),
    st.tuples(st.just("truncate"), REGION, st.integers(0, 10**6), st.just(0)),
    st.tuples(st.just("insert"), REGION, st.integers(0, 10**6), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("delete"), REGION, st.integers(0, 10**6), st.integers(1, 8)),
    st.tuples(st.just("set"), REGION, st.integers(0, 10**6), st.integers(0, 255)),
)


def mutate(data: bytes, mutations: list) -> bytes:
    """Apply mutations; each position is taken inside a region of the *original* message layout
    (envelope, JSON header, array bytes, or counted from the end) so all parts get hit."""
    buf = bytearray(data)
    hlen = struct.unpack_from("<I", data, 8)[0]
    for op, region, pos, arg in mutations:
        if not buf:
            break
        lo, hi = {"envelope": (0, 12), "header": (12, 12 + hlen), "arrays": (12 + hlen, len(data)),
                  "end": (max(0, len(buf) - 16), len(buf))}[region]
        hi = min(hi, len(buf))
        lo = min(lo, max(hi - 1, 0))
        i = lo + pos % max(hi - lo, 1)
        if op == "flip":
            buf[i % len(buf)] ^= 1 << arg
        elif op == "truncate":
            del buf[i:]
        elif op == "insert":
            buf[i:i] = arg
        elif op == "delete":
            del buf[i:i + arg]
        else:
            buf[i % len(buf)] = arg
    return bytes(buf)


def decodes_or_wire_error(data: bytes, schema: TransitionSchema) -> TransitionBatch | None:
    try:
        batch = decode_transitions(data, schema)
    except WireError as exc:
        assert exc.reason and isinstance(exc.reason, str)
        return None
    check_batch_fits(batch, schema)
    return batch


@FUZZ
@given(st.binary(max_size=2048))
def test_property_arbitrary_bytes(data):
    decodes_or_wire_error(data, SCHEMA)


@FUZZ
@given(st.integers(0, 600), st.binary(max_size=700))
def test_property_arbitrary_bytes_behind_a_valid_envelope(hlen, rest):
    decodes_or_wire_error(envelope(1, b"", hlen=hlen) + rest, SCHEMA)


@FUZZ
@given(valid_batches())
def test_property_valid_batches_round_trip(pair):
    batch, schema = pair
    out = decode_transitions(encode_transitions(batch), schema)
    check_batch_fits(out, schema)
    assert_same_batch(out, batch)


@FUZZ
@given(valid_batches(), st.lists(MUTATION, min_size=1, max_size=4))
def test_property_mutated_messages_decode_validly_or_raise_wire_error(pair, mutations):
    batch, schema = pair
    decodes_or_wire_error(mutate(encode_transitions(batch), mutations), schema)


@FUZZ
@given(st.sampled_from(["actor", "seq", "weights_version", "obs", "action", "reward", "terminated", "dtype",
                        "shape", "arrays", "extra", "<f4", "<i8", "|u1", "[", "]", "{", "}", ",", ":", '"']),
       st.binary(max_size=6), st.integers(0, 3))
def test_property_header_splices(token, junk, which):
    """Targeted mutations of the JSON header: splice bytes right after a field name or token."""
    msg = encode_transitions(make_batch(2))
    hlen = struct.unpack_from("<I", msg, 8)[0]
    head = msg[12:12 + hlen]
    positions = [m.end() for m in re.finditer(re.escape(token.encode()), head)]
    if not positions:
        return
    p = positions[which % len(positions)]
    new_head = head[:p] + junk + head[p:]
    for fix_len in (True, False):
        data = struct.pack("<4sHBBI", MAGIC, 1, 1, 0, len(new_head) if fix_len else hlen) + new_head + msg[12 + hlen:]
        decodes_or_wire_error(data, SCHEMA)


def _valid_messages() -> list[tuple[bytes, object]]:
    weights = encode_weights(Weights(2, 0, 5, {"a": np.ones((2, 2), np.float32), "b": np.zeros(3, np.int64)}))
    return [
        (weights, decode_weights),
        (encode_sample_request(SampleRequest(8, 2, 1, ("w0", "w1"))), decode_sample_request),
        (encode_batch(_sampled()), lambda d: decode_batch(d, SCHEMA)),
        (encode_json({"cmd": "stop", "n": [1, 2.5]}), decode_json),
        (encode_error("rate_limited", "x", 5), decode_error),
    ]


@FUZZ
@given(st.integers(0, 4), st.lists(MUTATION, min_size=1, max_size=3))
def test_property_every_decoder_raises_only_wire_error(which, mutations):
    data, decoder = _valid_messages()[which]
    try:
        decoder(mutate(data, mutations))
    except WireError:
        pass


def test_an_episode_record_round_trips_and_keeps_its_json_bytes():
    rec = wire.EpisodeRecord("w0", 12.5, 90, crashed=True, on_target_lane=False, weights_version=3, phase=2,
                             env_steps=1000, epsilon=0.25)
    data = wire.encode_episode(rec)
    assert wire.decode_episode(data) == rec
    # The same bytes the worker sent as a hand-built JSON body before the type existed.
    assert data == wire.encode_json({"actor": "w0", "return": 12.5, "length": 90, "crashed": True,
                                     "on_target_lane": False, "weights_version": 3, "phase": 2,
                                     "env_steps": 1000, "epsilon": 0.25})
    assert wire.decode_episode(wire.encode_json({"return": 1, "length": 2})) == wire.EpisodeRecord("", 1.0, 2)


@pytest.mark.parametrize("body, field", [
    ({"length": 2}, "'return' is required"),
    ({"return": "1", "length": 2}, "'return' must be float"),
    ({"return": 1.0, "length": -1}, "'length' must be >= 0"),
    ({"return": 1.0, "length": 2.5}, "'length' must be int"),
    ({"return": 1.0, "length": 2, "crashed": 1}, "'crashed' must be bool"),
    ({"return": 1.0, "length": 2, "actor": 7}, "'actor' must be str"),
])
def test_a_bad_episode_record_is_refused_naming_its_field(body, field):
    with pytest.raises(wire.WireError) as err:
        wire.decode_episode(wire.encode_json(body))
    assert err.value.reason == "bad_value" and field in str(err.value)


def test_the_safetensors_encoder_writes_the_packages_own_bytes():
    rng = np.random.default_rng(0)
    t = {"net.0.weight": rng.random((4, 3), dtype=np.float32), "net.0.bias": np.ones(4, np.float32),
         "a": np.arange(3, dtype=np.int64), "scalar": np.array(2.0, np.float32)}
    assert safetensors_dumps(t, {"version": "7"}) == stn.save(t, metadata={"version": "7"})
