"""``replay_server.http_api``: the replay server's HTTP JSON inspection API (no zenoh).

Online items are built so that every column is a function of the item's insertion key (see
``tmsg``): any item the API returns can be checked field by field, so a torn read (columns from
two different items) cannot pass unnoticed.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import math
import re
import signal
import socket
import threading
import time
import warnings
from urllib.parse import quote

import httpx
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.replay_server import http_api, http_models
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.http_api import make_app, serve_http
from laneshift.replay_server.stats_table import render
from laneshift.replay_server.storage import DemoTable
from laneshift.wire import SampleRequest, TransitionBatch, TransitionSchema

with warnings.catch_warnings():  # starlette >= 1.10 prefers httpx2 for its test client; httpx works
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

SCHEMA = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=5)
B = 7  # rows per ingested batch
FUZZ = settings(derandomize=True, database=None, deadline=None, max_examples=150,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


# --------------------------------------------------------------------------- helpers


def tmsg(start: int, rows: int = B) -> tuple[bytes, str]:
    """Batch number ``start // B`` of actor w0 / w1 alternately; every column derives from the key."""
    keys = np.arange(start, start + rows)
    batch_no = start // B
    actor = f"w{batch_no % 2}"
    obs = np.stack([keys, keys * 2, np.full(rows, 1.0)], axis=1).astype(np.float32)
    msg = wire.encode_transitions(TransitionBatch.from_arrays(
        actor=actor, seq=batch_no // 2, weights_version=batch_no, phase=0, env_steps=start + rows, obs=obs,
        action=keys % 5, reward=(keys / 10).astype(np.float32), next_obs=obs + 0.5, terminated=keys % 4 == 0,
        truncated=keys % 3 == 0))
    return msg, actor


def fill(core: ReplayCore, total: int) -> None:
    for _ in range(0, total, B):
        # Numbered on from the items received (stored or, in phase 1, dropped): each batch a new seq.
        msg, actor = tmsg(core.stats()["actors_total"]["items"])
        assert core.ingest(msg, actor) is None


def check_item(item: dict, with_obs: bool) -> None:
    """The item is exactly the one ``tmsg`` built for its key (all columns from one item)."""
    k = item["key"]
    assert item["actor"] == f"w{(k // B) % 2}" and item["weights_version"] == k // B
    assert item["action"] == k % 5 and item["reward"] == float(str(np.float32(k / 10)))
    assert item["terminated"] == (k % 4 == 0) and item["truncated"] == (k % 3 == 0)
    if with_obs:
        assert item["obs"] == [k, 2 * k, 1.0] and item["next_obs"] == [k + 0.5, 2 * k + 0.5, 1.5]
    else:
        assert "obs" not in item and "next_obs" not in item


def demo_table(n: int, metadata: dict | None = None) -> DemoTable:
    obs = np.zeros((n, 3), np.float32)
    obs[:, 0] = -(np.arange(n) + 1)
    return DemoTable(obs=obs, action=(np.arange(n) % 5).astype(np.int64), reward=np.full(n, 0.25, np.float32),
                     next_obs=obs + 100, terminated=(np.arange(n) % 7 == 0).astype(np.uint8), sha256="d" * 64,
                     metadata=metadata if metadata is not None else {"episodes": 3, "recorded_by": "scripted"})


def make_core(mode: str = "none", demo: int = 0, metadata: dict | None = None, **kw) -> ReplayCore:
    fields = {"capacity": 100, "min_size": 1, "samples_per_insert": 0.0, "demo_mode": mode, "seed": 5}
    if mode != "none":
        fields["demo_paths"] = ("unused",)
    fields.update(kw)
    return ReplayCore(ReplayConfig(**fields), SCHEMA, demo_table(demo, metadata) if demo else None)


def client(core: ReplayCore) -> TestClient:
    return TestClient(make_app(core))


def sample(core: ReplayCore, rows: int = 64) -> wire.SampledBatch:
    out = core.sample(SampleRequest(rows))
    assert isinstance(out, wire.SampledBatch), out
    return out


# --------------------------------------------------------------------------- /healthz


def test_healthz_ok_and_503_while_the_core_lock_is_stuck(monkeypatch):
    core = make_core()
    fill(core, 14)
    c = client(core)
    r = c.get("/healthz")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok" and body["mode"] == "none" and body["online_size"] == 14 and body["uptime_s"] >= 0
    monkeypatch.setattr(http_api, "HEALTH_LOCK_TIMEOUT_S", 0.05)
    with core.lock:
        r = c.get("/healthz")
    assert r.status_code == 503 and r.json()["status"] == "unavailable"


# --------------------------------------------------------------------------- /stats


def _keys_superset(got: dict, want: dict, path: str = "") -> None:
    for k, v in want.items():
        assert k in got, f"{path}{k} missing from /stats"
        if isinstance(v, dict) and v:
            _keys_superset(got[k], v, f"{path}{k}.")


def test_stats_has_everything_core_stats_has_plus_per_table_views():
    core = make_core("retention", demo=300, capacity=1000, demo_ratio=0.1)
    fill(core, 1400)  # the 900-item online region wraps
    for _ in range(20):
        sample(core, 256)
    body = client(core).get("/stats").json()
    want = core.stats()
    _keys_superset(body, want)
    stable = ("mode", "phase", "demo_share_buffer", "demo_share_recent_samples", "sampled_rows", "sampled_demo_rows",
              "requests", "rejected", "dropped", "actors", "checkpoint", "rate_limiter")
    assert {k: body[k] for k in stable} == {k: want[k] for k in stable}
    for name in ("online", "demo"):
        assert {k: body["tables"][name][k] for k in want["tables"][name]} == want["tables"][name]

    online, demo = body["tables"]["online"], body["tables"]["demo"]
    assert online["size"] == 900 and online["capacity"] == 900 and online["inserted"] == 1400
    assert demo["size"] == demo["capacity"] == 100 and demo["held"] == 300 and demo["sha256"] == "d" * 64
    assert online["share_buffer"] == pytest.approx(0.9) and demo["share_buffer"] == pytest.approx(0.1)
    assert online["share_recent_samples"] + demo["share_recent_samples"] == pytest.approx(1.0)
    assert online["sampled_rows"] + demo["sampled_rows"] == 20 * 256 == body["sampled_rows"]
    assert demo["sampled_rows"] == body["sampled_demo_rows"] > 0
    assert online["inserts_per_s"] == body["rates"]["inserts_per_s"] > 0 and demo["inserts_per_s"] == 0
    assert online["samples_per_s"] + demo["samples_per_s"] == pytest.approx(body["rates"]["samples_per_s"], abs=0.11)
    # Items in the buffer now, per actor: keys 500..1399, batches of 7 alternate w0 / w1.
    keys = np.arange(500, 1400)
    assert online["items_per_actor"] == {"w0": int(((keys // B) % 2 == 0).sum()),
                                         "w1": int(((keys // B) % 2 == 1).sum())}
    assert online["rate_limiter"] == body["rate_limiter"] and online["checkpoint_age_s"] is None
    assert "items_per_actor" not in demo
    assert "online" in render(body)  # `laneshift replay inspect` can render what /stats returns


def test_stats_checkpoint_age_and_rejections():
    core = make_core()
    fill(core, 21)
    core.last_checkpoint = {"items": 21, "seconds": 0.01, "path": "/x", "monotonic": time.monotonic() - 12.0}
    assert core.ingest(b"garbage", "w0") is not None
    body = client(core).get("/stats").json()
    assert 12.0 <= body["tables"]["online"]["checkpoint_age_s"] < 20.0
    assert body["checkpoint"]["items"] == 21 and sum(body["rejected"].values()) == 1


def test_stats_rehearsal_phase1_is_all_demo():
    core = make_core("rehearsal", demo=40)
    sample(core, 32)
    fill(core, 14)  # dropped in phase 1
    t = client(core).get("/stats").json()["tables"]
    assert t["demo"]["share_buffer"] == 1.0 and t["demo"]["share_recent_samples"] == 1.0
    assert t["online"]["share_buffer"] == 0.0 and t["online"]["size"] == 0 and t["online"]["items_per_actor"] == {}
    assert t["demo"]["sampled_rows"] == 32 and t["online"]["sampled_rows"] == 0


# --------------------------------------------------------------------------- /tables/{name}/items


def test_online_items_are_paged_from_the_oldest_after_wrap():
    core = make_core(capacity=30)
    fill(core, 70)  # keys 40..69 are live
    c = client(core)
    page = c.get("/tables/online/items").json()
    assert page["total"] == 30 and page["oldest_key"] == 40 and page["newest_key"] == 69
    assert page["offset"] == 0 and page["limit"] == 10 and page["next_offset"] == 10 and not page["include_obs"]
    assert page["obs_shape"] == [3] and page["obs_dtype"] == "<f4"
    assert [i["key"] for i in page["items"]] == list(range(40, 50))
    for item in page["items"]:
        check_item(item, with_obs=False)
    page = c.get("/tables/online/items", params={"offset": 25, "limit": 10, "include_obs": "true"}).json()
    assert [i["key"] for i in page["items"]] == list(range(65, 70)) and page["next_offset"] is None
    for item in page["items"]:
        check_item(item, with_obs=True)
    page = c.get("/tables/online/items", params={"offset": 30}).json()
    assert page["items"] == [] and page["total"] == 30 and page["next_offset"] is None


def test_limit_is_capped_at_100_and_keys_match_sampled_indices():
    core = make_core(capacity=300)
    fill(core, 280)
    c = client(core)
    page = c.get("/tables/online/items", params={"limit": 1000, "include_obs": True}).json()
    assert page["limit"] == 100 and len(page["items"]) == 100 and page["next_offset"] == 100
    b = sample(core, 16)
    by_key = {}
    for offset in (0, 100, 200):
        for item in c.get("/tables/online/items", params={"offset": offset, "limit": 100,
                                                          "include_obs": 1}).json()["items"]:
            by_key[item["key"]] = item
    assert sorted(by_key) == list(range(280))
    for row in range(16):  # the key the API shows is the index a sampled batch reports
        item = by_key[int(b.index[row])]
        assert item["obs"] == b.obs[row].tolist() and item["action"] == b.action[row]


def test_float32_obs_are_written_shortest_and_exact(monkeypatch):
    core = make_core()
    obs = np.array([[0.2, 1 / 3, -1e-7]] * 2, np.float32)
    assert core.ingest(wire.encode_transitions(TransitionBatch.from_arrays(
        actor="w0", seq=0, weights_version=0, phase=0, env_steps=2, obs=obs, action=[1, 2], reward=[0.1, 0.7],
        next_obs=obs * 3, terminated=[0, 0], truncated=[0, 1])), "w0") is None
    c = client(core)
    r = c.get("/tables/online/items", params={"include_obs": True})
    assert '"obs":[0.2,0.33333334,-1e-07]' in r.text and '"reward":0.1,' in r.text
    monkeypatch.setattr(http_models, "SHORT_FLOATS_MAX", 0)  # big pages: float64 of the same float32 values
    long = c.get("/tables/online/items", params={"include_obs": True})
    assert '"obs":[0.20000000298023224,' in long.text
    for body in (r.json(), long.json()):
        got = np.array([i["obs"] for i in body["items"]], np.float32)
        assert np.array_equal(got, obs) and np.array_equal(np.array([i["next_obs"] for i in body["items"]],
                                                                    np.float32), obs * 3)
        assert [np.float32(i["reward"]) for i in body["items"]] == [np.float32(0.1), np.float32(0.7)]


def test_demo_items_are_the_sampled_demo_region():
    core = make_core("retention", demo=300, capacity=1000, demo_ratio=0.1)
    page = client(core).get("/tables/demo/items", params={"offset": 95, "limit": 50, "include_obs": True}).json()
    assert page["total"] == 100 and page["oldest_key"] == 0 and page["newest_key"] == 99
    assert [i["key"] for i in page["items"]] == list(range(95, 100))
    for item in page["items"]:
        k = item["key"]
        assert set(item) == {"key", "action", "reward", "steps", "terminated", "obs", "next_obs"}  # no actor / truncated
        assert item["obs"] == core.demo.obs[k].tolist() and item["next_obs"] == core.demo.next_obs[k].tolist()
        assert item["action"] == core.demo.action[k] and item["reward"] == 0.25
        assert item["terminated"] == bool(core.demo.terminated[k])
        assert item["steps"] == int(core.demo.steps[k]) == 1


def test_items_show_priorities_with_the_prioritized_sampler():
    core = make_core(capacity=50, sampler="prioritized")
    fill(core, 14)
    items = client(core).get("/tables/online/items").json()["items"]
    assert [i["priority"] for i in items] == pytest.approx(core.selector.priority_of(np.arange(10)).tolist())
    assert "priority" not in client(make_core()).get("/tables/online/items").json()["items"]


def test_items_are_whole_under_concurrent_ingest():
    core = make_core(capacity=50)
    fill(core, 56)  # full from the start: every page below has 50 items
    stop = threading.Event()
    errors = []

    def ingest() -> None:
        while not stop.is_set():
            msg, actor = tmsg(core.online.inserted)
            if (err := core.ingest(msg, actor)) is not None:
                errors.append(err)
            time.sleep(0)  # lets the reader's threads take the GIL between messages, as a socket wait would

    thread = threading.Thread(target=ingest, daemon=True)
    c = client(core)
    oldest = set()
    thread.start()
    try:
        # Until the pages have shown several tables, not for a fixed time: on a fast machine the
        # ingest loop held the GIL so long that 0.8 s gave the reader two pages (a fresh clone).
        deadline = time.monotonic() + 30
        while len(oldest) < 8 and time.monotonic() < deadline:
            for offset in (0, 40):
                page = c.get("/tables/online/items", params={"offset": offset, "limit": 100,
                                                              "include_obs": True}).json()
                assert page["total"] == 50 and len(page["items"]) == 50 - offset
                assert [i["key"] for i in page["items"]] == list(range(page["oldest_key"] + offset,
                                                                       page["newest_key"] + 1))
                for item in page["items"]:
                    check_item(item, with_obs=True)
                oldest.add(page["oldest_key"])
    finally:
        stop.set()
        thread.join(5)
    assert not errors
    assert len(oldest) > 3, "the ingest thread hardly ran: the test proved nothing"


# --------------------------------------------------------------------------- /demo


def test_demo_endpoint_metadata_and_sizes():
    core = make_core("none", demo=20, metadata={"episodes": 3, "env_id": "laneshift/Straight-v0", "bad": math.nan})
    body = client(core).get("/demo").json()
    assert body["loaded"] and body["sha256"] == "d" * 64 and body["held_items"] == 20
    assert body["buffer_items"] == 0 and not body["sampled"]  # mode none holds demos but never samples them
    assert body["held_bytes"] == core.demo_held.nbytes
    assert body["metadata"] == {"episodes": 3, "env_id": "laneshift/Straight-v0", "bad": None}  # NaN -> null
    body = client(make_core("retention", demo=300, capacity=1000)).get("/demo").json()
    assert body["buffer_items"] == 100 and body["sampled"] and body["mode"] == "retention"
    body = client(make_core()).get("/demo").json()
    assert not body["loaded"] and body["sha256"] is None and body["held_items"] == 0 and body["metadata"] == {}


# --------------------------------------------------------------------------- /metrics

_SAMPLE = re.compile(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{((?:[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\\n]|\\[\\"n])*",?)*)\})? '
                     r'(-?[0-9.e+-]+|NaN|[+-]Inf)$')
_LABEL = re.compile(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\\n]|\\[\\"n])*)"')


def parse_metrics(text: str) -> dict[tuple[str, tuple], float]:
    """A strict reader of the text format 0.0.4 (what a Prometheus scrape needs). Labels come
    back sorted by name; a histogram's ``_bucket`` / ``_sum`` / ``_count`` lines belong to its family."""
    assert text.endswith("\n")
    types, out = {}, {}
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split(" ")
            assert kind in ("counter", "gauge", "histogram") and name not in types
            assert name.startswith(("laneshift_replay_", "process_")), name
            assert (kind == "counter") == name.endswith("_total"), f"{name} ({kind}): _total is for counters only"
            types[name] = kind
        elif line.startswith("# HELP "):
            assert len(line.split(" ", 3)) == 4
        else:
            m = _SAMPLE.match(line)
            assert m, f"not a valid sample line: {line!r}"
            name = m.group(1)
            family = re.sub(r"_(bucket|sum|count)$", "", name)
            assert name in types or types.get(family) == "histogram", name
            labels = tuple(sorted(_LABEL.findall(m.group(3) or "")))
            assert (name, labels) not in out
            out[(name, labels)] = float(m.group(4))
    return out


def test_metrics_exposition_format_and_values():
    core = make_core("retention", demo=300, capacity=1000, demo_ratio=0.1)
    fill(core, 140)
    sample(core, 100)
    core.reject('we"ird\\reason\nx')  # label values are escaped
    core.last_checkpoint = {"items": 140, "seconds": 0.5, "path": "/x", "monotonic": time.monotonic() - 3}
    r = client(core).get("/metrics")
    assert r.status_code == 200 and r.headers["content-type"] == "text/plain; version=0.0.4; charset=utf-8"
    m = parse_metrics(r.text)
    st_ = core.stats()
    assert m[("laneshift_replay_table_size", (("table", "online"),))] == 140
    assert m[("laneshift_replay_table_size", (("table", "demo"),))] == 100
    assert m[("laneshift_replay_table_capacity", (("table", "online"),))] == 900
    assert m[("laneshift_replay_inserted_total", (("table", "online"),))] == 140
    assert (m[("laneshift_replay_sampled_rows_total", (("table", "online"),))]
            + m[("laneshift_replay_sampled_rows_total", (("table", "demo"),))]) == 100
    assert m[("laneshift_replay_sampled_rows_total", (("table", "demo"),))] == st_["sampled_demo_rows"]
    assert m[("laneshift_replay_rejected_total", (("reason", 'we\\"ird\\\\reason\\nx'),))] == 1
    assert m[("laneshift_replay_actor_buffer_items", (("actor", "w0"),))] == 70
    assert m[("laneshift_replay_actor_items_total", (("actor", "w1"),))] == 70
    assert m[("laneshift_replay_demo_share_ratio", (("scope", "buffer"),))] == pytest.approx(100 / 240)
    assert m[("laneshift_replay_demo_share_ratio", (("scope", "recent_samples"),))] == st_["demo_share_recent_samples"]
    assert 3 <= m[("laneshift_replay_checkpoint_age_seconds", ())] < 10
    assert m[("laneshift_replay_info", (("demo_sha256", "d" * 64), ("mode", "retention")))] == 1
    assert m[("laneshift_replay_sample_requests_total", (("result", "served"),))] == 1
    assert m[("laneshift_replay_actor_env_steps_total", (("actor", "w1"),))] == 140
    # Rates are Prometheus's job (rate() over these counters): no server-side per-second gauges.
    assert not any(name.endswith("_per_second") for name, _ in m)
    assert m[("process_resident_memory_bytes", ())] > 0 and m[("process_cpu_seconds_total", ())] >= 0
    # Before any checkpoint or ratio, those gauges are absent (their HELP / TYPE stay).
    text = client(make_core()).get("/metrics").text
    assert "\nlaneshift_replay_checkpoint_age_seconds" not in text and "TYPE laneshift_replay_checkpoint_age" in text
    assert "\nlaneshift_replay_wal_bytes" not in text and "TYPE laneshift_replay_wal_bytes" in text  # no log
    parse_metrics(text)


def test_metrics_of_the_write_ahead_log(tmp_path):
    from laneshift.replay_server.wal import WriteAheadLog

    core = make_core()
    core.wal = WriteAheadLog(tmp_path / "wal", "write", {}, 0, first_gen=1)
    core.wal.write_transitions("w0", b"x" * 100)
    m = parse_metrics(client(core).get("/metrics").text)
    assert m[("laneshift_replay_wal_records_total", ())] == 1 and m[("laneshift_replay_wal_failures_total", ())] == 0
    assert m[("laneshift_replay_wal_bytes", ())] > 100


def test_metrics_sample_latency_histogram():
    from laneshift.replay_server.service import SampleLatency

    core = make_core()
    text = client(core).get("/metrics").text  # no zenoh service: the histogram has no series yet
    assert "# TYPE laneshift_replay_sample_duration_seconds histogram" in text
    assert "laneshift_replay_sample_duration_seconds_count" not in text
    core.sample_latency = latency = SampleLatency()
    for seconds in (0.0004, 0.0005, 0.003, 0.2, 9.0):
        latency.observe("batch", seconds)
    latency.observe("error", 0.0001)
    m = parse_metrics(client(core).get("/metrics").text)
    name = "laneshift_replay_sample_duration_seconds"
    buckets = {float(dict(labels)["le"]): v for (n, labels), v in m.items()
               if n == name + "_bucket" and dict(labels)["result"] == "batch"}
    assert buckets[0.0005] == 2 and buckets[0.0025] == 2 and buckets[0.005] == 3 and buckets[2.5] == 4
    assert buckets[math.inf] == 5 == m[(name + "_count", (("result", "batch"),))]
    assert m[(name + "_sum", (("result", "batch"),))] == pytest.approx(9.2039)
    assert list(buckets.values()) == sorted(buckets.values())  # cumulative
    assert m[(name + "_count", (("result", "error"),))] == 1


# --------------------------------------------------------------------------- /info


def test_info_says_what_transitions_must_look_like():
    core = make_core("retention", demo=300, capacity=1000)
    core.identity, core.http_url = {"run_id": "r1"}, "http://127.0.0.1:1"
    body = client(core).get("/info").json()
    assert body == {"wire_version": wire.WIRE_VERSION, "obs_shape": [3], "obs_dtype": "<f4", "n_actions": 5,
                    "run_id": "r1", "mode": "retention", "http_url": "http://127.0.0.1:1"}
    stats = client(core).get("/stats").json()  # the stats reply carries the same three
    assert (stats["obs_shape"], stats["obs_dtype"], stats["n_actions"]) == ([3], "<f4", 5)
    assert client(make_core()).get("/info").json()["run_id"] is None  # a core outside a server has no run


# --------------------------------------------------------------------------- bad parameters, schema


BAD = [
    ("/tables/online/items?offset=-1", 422, "offset"),
    ("/tables/online/items?limit=0", 422, "limit"),
    ("/tables/online/items?limit=-5", 422, "limit"),
    ("/tables/online/items?limit=1.5", 422, "limit"),
    ("/tables/online/items?limit=ten", 422, "limit"),
    ("/tables/online/items?offset=", 422, "offset"),
    ("/tables/online/items?offset=1e3", 422, "offset"),
    ("/tables/online/items?include_obs=maybe", 422, "include_obs"),
    ("/tables/replay/items", 404, "unknown table"),
    ("/tables/ONLINE/items", 404, "unknown table"),
    ("/tables/%00/items", 404, "unknown table"),
    ("/tables/online", 404, "Not Found"),
    ("/nothing", 404, "Not Found"),
]


@pytest.mark.parametrize(("url", "status", "says"), BAD)
def test_bad_parameters_get_a_4xx_with_a_message(url, status, says):
    core = make_core()
    fill(core, 14)
    r = client(core).get(url)
    assert r.status_code == status, r.text
    assert says in r.text


def test_wrong_method_is_405():
    c = client(make_core())
    assert c.post("/stats").status_code == 405 and c.delete("/tables/online/items").status_code == 405


_JUNK = st.one_of(
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["", "0", "1", "100", "101", "-0", "+3", " 2", "1.0", "1e2", "NaN", "inf", "0x10", "true",
                     "9" * 5000, "\u0661", "\x00", "%", "1/2", "[]"]),
    st.text(max_size=12),
)

_FUZZ_CORE = make_core("retention", demo=300, capacity=1000, demo_ratio=0.1)
fill(_FUZZ_CORE, 63)
_FUZZ_CLIENT = client(_FUZZ_CORE)


@FUZZ
@given(name=st.one_of(st.sampled_from(["online", "demo"]), st.text(max_size=10)), offset=_JUNK, limit=_JUNK,
       include_obs=_JUNK, path=st.sampled_from(["/healthz", "/stats", "/demo", "/info", "/metrics", "/openapi.json",
                                                "items"]))
def test_no_parameters_make_a_5xx(name, offset, limit, include_obs, path):
    params = {"offset": offset, "limit": limit, "include_obs": include_obs}
    url = f"/tables/{quote(name, safe='')}/items" if path == "items" else path
    r = _FUZZ_CLIENT.get(url, params=params)
    assert r.status_code < 500, (url, params, r.text)
    if r.status_code == 200 and path == "items":
        page = r.json()
        assert len(page["items"]) <= 100 and page["total"] == {"online": 63, "demo": 100}[name]  # fill() rounds up to whole batches


def test_openapi_schema_documents_the_endpoints():
    schema = client(make_core()).get("/openapi.json").json()
    assert {"/healthz", "/stats", "/tables/{name}/items", "/demo", "/info", "/metrics"} <= set(schema["paths"])
    params = {p["name"]: p for p in schema["paths"]["/tables/{name}/items"]["get"]["parameters"]}
    assert params["offset"]["schema"]["minimum"] == 0 and params["limit"]["schema"]["minimum"] == 1
    assert params["limit"]["schema"]["default"] == 10 and params["include_obs"]["schema"]["type"] == "boolean"
    assert "ItemsPage" in schema["components"]["schemas"]


# --------------------------------------------------------------------------- serve_http


def test_serve_http_binds_loopback_serves_and_stops_without_touching_signals():
    core = make_core()
    fill(core, 14)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    stop = threading.Event()
    thread, port = serve_http(core, port=0, stop=stop)
    try:
        assert port > 0 and thread.daemon and thread.is_alive()
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=5) as h:
            assert h.get("/healthz").json()["status"] == "ok"
            assert h.get("/tables/online/items", params={"limit": 2}).json()["items"][1]["key"] == 1
            assert h.get("/tables/online/items", params={"limit": 0}).status_code == 422
        assert {s: signal.getsignal(s) for s in before} == before
        with pytest.raises(OSError):  # the port is really taken (bound before serve_http returned)
            serve_http(core, port=port, stop=stop)
    finally:
        stop.set()
        thread.join(5)
    assert not thread.is_alive()
    assert {s: signal.getsignal(s) for s in before} == before
    with socket.socket() as s:  # the port was released
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))
