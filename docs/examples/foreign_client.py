"""A laneshift client written from docs/wire.md alone: what a program in another language does.

What it is: an example, run by tests/test_docs_examples.py against a standalone replay server
(docs/wire.md §12 says how to start one). It asks ``replay/info`` what observations look like,
builds a TRANSITIONS message byte by byte, publishes it, samples the rows back and checks them,
and checks two documented refusals (a kind-7 message on a transitions key counts as
``wrong_kind``; a header without ``"arrays"`` is answered ``bad_request``).
Room: docs example (a client in another program). May import: the Python standard library and ``zenoh`` (eclipse-zenoh 1.x) only. Nothing from
laneshift, not even numpy: every byte is packed and parsed here, as docs/wire.md describes.

    python docs/examples/foreign_client.py --router tcp/127.0.0.1:7447 --run-id run

Exit code 0 when every check passed; it prints what it did as it goes. Run it against a fresh
server in mode ``none`` (as §12 starts it): it checks that every sampled row is one it sent.
"""

from __future__ import annotations

import argparse
import json
import math
import struct
import sys
import time
import urllib.request

import zenoh

ENVELOPE = struct.Struct("<4sHBBI")  # §2: magic, wire version, kind, reserved, header length
WIRE_VERSION = 2
KIND_TRANSITIONS, KIND_SAMPLE_REQUEST, KIND_BATCH, KIND_ERROR, KIND_JSON, KIND_PRIORITIES = 1, 3, 4, 5, 6, 7
# §3: dtype code -> struct format of one little-endian value (the codes this client needs).
STRUCT = {"|u1": "B", "|b1": "?", "|i1": "b", "<i2": "h", "<u2": "H", "<i4": "i", "<u4": "I", "<i8": "q",
          "<f2": "e", "<f4": "f", "<f8": "d"}


# --------------------------------------------------------------------------- §2, §3: envelope and arrays


def encode(kind: int, fields: dict, arrays: list[tuple[str, str, list[int], list]]) -> bytes:
    """A message: ``arrays`` are (name, dtype code, shape, flat values in C order)."""
    header = dict(fields, arrays=[{"name": n, "dtype": d, "shape": s} for n, d, s, _ in arrays])
    head = json.dumps(header, separators=(",", ":")).encode()
    body = b"".join(struct.pack(f"<{len(v)}{STRUCT[d]}", *v) for _, d, _, v in arrays)
    return ENVELOPE.pack(b"LSHF", WIRE_VERSION, kind, 0, len(head)) + head + body


def decode(msg: bytes) -> tuple[int, dict, dict[str, tuple[list[int], list]]]:
    """(kind, header fields, {name: (shape, flat values)}); the §4 checks a client needs."""
    magic, version, kind, reserved, hlen = ENVELOPE.unpack_from(msg, 0)
    assert magic == b"LSHF" and version == WIRE_VERSION and reserved == 0, (magic, version, reserved)
    header = json.loads(msg[12:12 + hlen])
    offset, arrays = 12 + hlen, {}
    for spec in header.pop("arrays"):
        count = math.prod(spec["shape"])
        fmt = f"<{count}{STRUCT[spec['dtype']]}"
        arrays[spec["name"]] = (spec["shape"], list(struct.unpack_from(fmt, msg, offset)))
        offset += struct.calcsize(fmt)
    assert offset == len(msg), "trailing bytes"
    return kind, header, arrays


def json_body(msg: bytes) -> dict:
    """§5.6: a JSON message is a header ``{"body": {...}, "arrays": []}``."""
    kind, header, _ = decode(msg)
    assert kind == KIND_JSON, f"expected a JSON message, got kind {kind}"
    return header["body"]


# --------------------------------------------------------------------------- §1: zenoh


def open_session(router: str) -> zenoh.Session:
    """A zenoh client of the run's router, with §1's settings (one-shot: give up after 10 s)."""
    conf = zenoh.Config()
    for key, value in {"mode": "client", "connect/endpoints": [router], "listen/endpoints": [],
                       "scouting/multicast/enabled": False, "scouting/gossip/enabled": False,
                       "transport/shared_memory/enabled": False,
                       "connect/timeout_ms": 10000, "connect/exit_on_failure": True}.items():
        conf.insert_json5(key, json.dumps(value))
    return zenoh.open(conf)


def query(session: zenoh.Session, key: str, payload: bytes | None = None, timeout_s: float = 5.0,
          retry_s: float = 0.0) -> bytes:
    """§1: the first Ok reply; no reply within the timeout means nobody answered. ``retry_s``: ask
    again for that long (a server that just wrote its ready file may not be known to the router yet)."""
    deadline = time.monotonic() + retry_s
    while True:
        for reply in session.get(key, payload=payload, timeout=timeout_s):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        if time.monotonic() >= deadline:
            raise SystemExit(f"nobody answered on {key}")
        time.sleep(0.1)


def stats(session: zenoh.Session, run: str) -> dict:
    return json_body(query(session, f"laneshift/{run}/replay/stats"))


# --------------------------------------------------------------------------- the walk-through


def transitions(info: dict, actor: str, rows: int) -> tuple[bytes, list[tuple]]:
    """§5.1: ``rows`` transitions whose observations say which row they are (obs[0] = row + 1)."""
    size = math.prod(info["obs_shape"])
    obs, next_obs, sent = [], [], []
    for i in range(rows):
        row = [i + 1] + [0] * (size - 1)
        obs += row
        next_obs += [i + 2] + [0] * (size - 1)
        sent.append((tuple(row), i % info["n_actions"]))
    fields = {"actor": actor, "seq": 0, "weights_version": 0, "phase": 0, "env_steps": rows}
    shape = [rows, *info["obs_shape"]]
    return encode(KIND_TRANSITIONS, fields, [
        ("obs", info["obs_dtype"], shape, obs),
        ("action", "<i8", [rows], [a for _, a in sent]),
        ("reward", "<f4", [rows], [0.5] * rows),
        ("next_obs", info["obs_dtype"], shape, next_obs),
        ("terminated", "|u1", [rows], [0] * rows),
        ("truncated", "|u1", [rows], [0] * (rows - 1) + [1]),
        ("steps", "|u1", [rows], [1] * rows),
    ]), sent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--router", required=True, help="the run's zenoh router endpoint, e.g. tcp/127.0.0.1:7447")
    ap.add_argument("--run-id", required=True, help="transport.run_id of the replay server")
    ap.add_argument("--actor", default="foreign0", help="this client's actor name, [A-Za-z0-9_-]{1,64}")
    ap.add_argument("--rows", type=int, default=8, help="transitions to send")
    args = ap.parse_args()
    run, actor = args.run_id, args.actor

    with open_session(args.router) as session:
        # 1. What observations and actions look like (§7, replay/info).
        info = json_body(query(session, f"laneshift/{run}/replay/info", retry_s=10))
        print(f"replay/info: {info}", flush=True)
        assert info["wire_version"] == WIRE_VERSION and info["run_id"] == run
        if info["http_url"]:  # the HTTP API's /info says the same
            with urllib.request.urlopen(info["http_url"] + "/info", timeout=5) as resp:
                assert json.load(resp) == info
            print(f"GET {info['http_url']}/info: the same", flush=True)

        # 2. Publish one TRANSITIONS message (§5.1) with BLOCK, once the server's subscriber matches (§1).
        msg, sent = transitions(info, actor, args.rows)
        pub = session.declare_publisher(f"laneshift/{run}/transitions/{actor}",
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 10
        while not pub.matching_status.matching:
            assert time.monotonic() < deadline, "no replay server subscribes to transitions"
            time.sleep(0.01)
        before = stats(session, run)["rejected"].get("wrong_kind", 0)
        pub.put(msg)
        # A well-formed message of another kind (7, PRIORITIES) on a transitions key: counted, not stored (§4, §10).
        pub.put(encode(KIND_PRIORITIES, {}, [("index", "<i8", [1], [0]), ("is_demo", "|u1", [1], [0]),
                                             ("priority", "<f4", [1], [1.0])]))
        print(f"published {len(msg)} bytes: {args.rows} transitions as {actor}, seq 0; and one kind-7 message",
              flush=True)

        # 3. Wait until the server counted both (§10: stats.actors, stats.rejected).
        deadline = time.monotonic() + 10
        while True:
            s = stats(session, run)
            stored = s["actors"].get(actor, {}).get("stored", 0)
            if stored >= args.rows and s["rejected"].get("wrong_kind", 0) > before:
                break
            assert time.monotonic() < deadline, f"server stored {stored} rows; rejected {s['rejected']}"
            time.sleep(0.05)
        assert (s["obs_shape"], s["obs_dtype"], s["n_actions"]) == (info["obs_shape"], info["obs_dtype"],
                                                                     info["n_actions"])
        print(f"replay/stats: {actor} stored {stored}; rejected {s['rejected']}", flush=True)

        # 4. Sample them back (§5.3 -> §5.4); retry while rate limited or not ready (§5.5).
        request = encode(KIND_SAMPLE_REQUEST, {"batch_size": args.rows, "num_batches": 1, "min_version": -1,
                                               "actors": []}, [])
        deadline = time.monotonic() + 10
        while True:
            kind, header, arrays = decode(query(session, f"laneshift/{run}/replay/sample", request))
            if kind == KIND_BATCH:
                break
            assert kind == KIND_ERROR and header["reason"] in ("rate_limited", "not_ready"), header
            assert time.monotonic() < deadline, header
            time.sleep(max(header["retry_after_ms"], 1) / 1000)
        shape, obs = arrays["obs"]
        size = math.prod(info["obs_shape"])
        assert shape == [args.rows, *info["obs_shape"]] and header["num_batches"] == 1
        got = [(tuple(obs[i * size:(i + 1) * size]), arrays["action"][1][i]) for i in range(args.rows)]
        assert all(row in sent for row in got), "a sampled row is not one this client sent"
        assert set(arrays["is_demo"][1]) == {0} and set(arrays["steps"][1]) == {1}
        print(f"replay/sample: a BATCH of {args.rows} rows, every one of them sent above "
              f"(keys {sorted(arrays['index'][1])})", flush=True)

        # 5. "Header only" still means an "arrays" list (§3, §5.3): without one, bad_request.
        fields = json.dumps({"batch_size": 1, "num_batches": 1, "min_version": -1}).encode()
        bad = ENVELOPE.pack(b"LSHF", WIRE_VERSION, KIND_SAMPLE_REQUEST, 0, len(fields)) + fields
        kind, header, _ = decode(query(session, f"laneshift/{run}/replay/sample", bad))
        assert kind == KIND_ERROR and header["reason"] == "bad_request", header
        print(f"a SAMPLE_REQUEST without \"arrays\": ERROR {header['reason']} ({header['detail']})", flush=True)
    print("ok", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
