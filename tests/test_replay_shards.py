"""A sharded replay (``replay.shards``): routing, each shard's config, the learner's sampling across
shards (uniform over the union, retention's demo share, priorities and their importance weights,
refusals), the stats of all shards as one, and in-process runs on 2 shards.

The shards here are real ``ReplayCore`` objects behind ``deploy.inprocess.InProcessReplay`` (wire
bytes in and out, as over zenoh); the sampling is ``learner.shards.ShardedReplay``. Online items
are traceable: ``obs[:, 0]`` is the item's insertion key, ``obs[:, 1]`` the shard it was sent to.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ConfigError, ReplayConfig, load_run_config
from laneshift.deploy.inprocess import InProcessReplay, train_inprocess
from laneshift.learner.shards import ShardedReplay, split_rows
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.storage import DemoTable
from laneshift.replay_stats import merge_replay_stats
from laneshift.wire import SampleRequest, TransitionBatch, TransitionSchema

SCHEMA = TransitionSchema(obs_shape=(3,), obs_dtype="float32", n_actions=5)


def transitions(actor: str, shard: int, start: int, rows: int, seq: int) -> bytes:
    obs = np.zeros((rows, 3), np.float32)
    obs[:, 0] = np.arange(start, start + rows)
    obs[:, 1] = shard
    return wire.encode_transitions(TransitionBatch.from_arrays(
        actor=actor, seq=seq, weights_version=0, phase=0, env_steps=start + rows, obs=obs,
        action=np.arange(rows) % 5, reward=np.ones(rows, np.float32), next_obs=obs + 0.5,
        terminated=np.zeros(rows), truncated=np.zeros(rows)))


def demo_table(n: int) -> DemoTable:
    obs = np.full((n, 3), -1.0, np.float32)
    return DemoTable(obs=obs, action=np.zeros(n, np.int64), reward=np.zeros(n, np.float32), next_obs=obs,
                     terminated=np.zeros(n, np.uint8), sha256="d" * 64, metadata={"episodes": 1})


def cores(shards: int, fill: list[int], **replay) -> list[ReplayCore]:
    """``shards`` cores of one run's sharded replay, shard i filled with ``fill[i]`` items by one actor."""
    fields = {"capacity": 1000, "min_size": shards, "samples_per_insert": 0.0, "shards": shards, **replay}
    if fields.get("demo_mode", "none") != "none":
        fields["demo_paths"] = ("unused",)
    cfg = ReplayConfig(**fields)
    out = []
    for i in range(shards):
        demo = demo_table(500) if fields.get("demo_paths") else None
        core = ReplayCore(cfg.shard(i), SCHEMA, demo)
        for seq, start in enumerate(range(0, fill[i], 50)):
            assert core.ingest(transitions(f"w{i}", i, start, min(50, fill[i] - start), seq)) is None
        out.append(core)
    return out


def sharded(cs: list[ReplayCore], beta: float = 0.4) -> ShardedReplay:
    return ShardedReplay([InProcessReplay(c, SCHEMA) for c in cs], beta=beta, seed=0)


# --------------------------------------------------------------------------- routing and config


def test_routing_is_a_stable_function_of_the_name_and_spreads_numbered_workers():
    assert [wire.shard_of(f"w{i}", 4) for i in range(8)] == [0, 1, 2, 3, 0, 1, 2, 3]
    assert wire.shard_of("w7", 1) == 0
    named = [wire.shard_of(f"robot-{c}", 4) for c in "abcdefghijklmnopqrstuvwxyz"]
    assert named == [wire.shard_of(f"robot-{c}", 4) for c in "abcdefghijklmnopqrstuvwxyz"]  # stable
    assert len(set(named)) == 4  # CRC-32 spreads names without a number over every shard
    with pytest.raises(ValueError):
        wire.shard_of("bad/name", 2)


def test_one_shard_keeps_the_keys_of_one_server_and_shards_get_their_own():
    assert wire.replay_namespace("run", 0, 1) == "run"
    assert wire.sample_key(wire.replay_namespace("run", 0, 1)) == "laneshift/run/replay/sample"
    ns = wire.replay_namespace("run", 2, 3)
    assert wire.sample_key(ns) == "laneshift/run/shard-2/replay/sample"
    assert wire.transitions_key(ns, "w2") == "laneshift/run/shard-2/transitions/w2"
    assert wire.actor_from_transitions_key(wire.transitions_key(ns, "w2")) == "w2"
    for bad in ((0, 0), (3, 3), (0, wire.MAX_SHARDS + 1)):
        with pytest.raises(ValueError):
            wire.replay_namespace("run", *bad)


def test_each_shard_takes_its_share_of_capacity_and_min_size():
    cfg = ReplayConfig(capacity=1001, min_size=100, shards=4, http_port=9000, seed=5)
    parts = [cfg.shard(i) for i in range(4)]
    assert sum(p.capacity for p in parts) == 1001 and sum(p.min_size for p in parts) == 100
    assert [p.seed for p in parts] == [5, 6, 7, 8] and [p.http_port for p in parts] == [9000, 9001, 9002, 9003]
    assert all(p.shards == 1 for p in parts)
    assert ReplayConfig(capacity=10, min_size=1).shard(0) is not None
    with pytest.raises(ConfigError, match="replay.shards"):
        ReplayConfig(capacity=100, min_size=1, shards=2)  # a shard would have no min_size of its own
    with pytest.raises(ConfigError, match="replay.shards"):
        ReplayConfig(shards=65)


def test_split_rows_is_proportional_and_exact():
    assert split_rows(256, [1, 1]) == [128, 128]
    assert sum(split_rows(257, [3, 1, 0])) == 257 and split_rows(257, [3, 1, 0])[2] == 0
    assert split_rows(10, [0, 0]) == [5, 5]


# --------------------------------------------------------------------------- sampling across shards


def test_uniform_sampling_is_uniform_over_the_union_of_shards():
    replay = sharded(cores(2, [600, 200], capacity=2000))
    replay.sample(SampleRequest(64))  # the first request splits evenly; its replies tell the sizes
    batch = replay.sample(SampleRequest(256, 16))
    from_shard0 = float(np.mean(batch.obs[:, 1] == 0))
    assert abs(from_shard0 - 0.75) < 0.01  # 600 of 800 items: split by size, exactly up to rounding
    assert batch.num_batches == 16 and len(batch.action) == 4096
    # Rows are mixed: every minibatch holds items of both shards.
    assert all(0 < np.mean(part) < 1 for part in np.split(batch.obs[:, 1], 16))
    # Keys name the shard: key * N + shard.
    assert np.array_equal(batch.index % 2, batch.obs[:, 1].astype(np.int64))
    assert np.array_equal(batch.index // 2, batch.obs[:, 0].astype(np.int64))


def test_retention_keeps_its_demo_share_across_shards():
    cs = cores(2, [900, 900], demo_mode="retention", demo_ratio=0.1, capacity=2000)
    replay = sharded(cs)
    replay.sample(SampleRequest(64))
    demo = [replay.sample(SampleRequest(512, 8)).is_demo.mean() for _ in range(5)]
    assert abs(float(np.mean(demo)) - 0.1) < 0.01
    assert merge_replay_stats([c.stats() for c in cs])["demo_share_buffer"] == pytest.approx(0.1)
    # Each shard drew its own demo subset (seed + shard).
    assert cs[0].demo.size == cs[1].demo.size == 100


def test_a_request_without_next_obs_asks_every_shard_without_and_merges_the_rest():
    cs = cores(2, [300, 300], demo_mode="retention", demo_ratio=0.1, capacity=2000)
    whole, part = sharded(cs).sample(SampleRequest(64, 2)), sharded(cs).sample(SampleRequest(64, 2, next_obs=False))
    assert whole.next_obs is not None and part.next_obs is None
    assert len(part.action) == 128 and part.num_batches == 2 and set(part.info["shards"]) == {0, 1}
    assert part.is_demo.any() and not part.is_demo.all()  # both tables, both shards
    online = ~part.is_demo.astype(bool)
    assert np.array_equal(part.obs[online, 0], (part.index[online] // 2).astype(np.float32))  # key = shard key * n + i
    assert np.array_equal(part.obs[online, 1], (part.index[online] % 2).astype(np.float32))


def test_prioritized_shards_sample_by_mass_with_the_union_importance_weights():
    cs = cores(2, [400, 400], sampler="prioritized", priority_alpha=1.0)
    # Shard 1's items are 3x as likely as shard 0's: it should get 3/4 of the rows.
    for core, priority in zip(cs, (1.0, 3.0)):
        keys = np.arange(400, dtype=np.int64)
        core.update_priorities(wire.PriorityUpdate(index=keys, is_demo=np.zeros(400, np.uint8),
                                                   priority=np.full(400, priority - core.cfg.priority_eps,
                                                                    np.float32)))
    beta = 0.5
    replay = sharded(cs, beta=beta)
    replay.sample(SampleRequest(64))
    batch = replay.sample(SampleRequest(256, 16))
    shard = batch.obs[:, 1].astype(int)
    assert abs(float(np.mean(shard == 1)) - 0.75) < 0.01
    # One sum tree over both shards would give weight (N p / M)^-beta, normalised by the maximum:
    # items of priority 1 (shard 0) weigh 3^beta times those of priority 3.
    assert batch.weight.max() == pytest.approx(1.0)
    assert np.allclose(batch.weight[shard == 0], 1.0)
    assert np.allclose(batch.weight[shard == 1], 3.0 ** -beta, rtol=1e-5)


def test_priority_updates_go_back_to_the_shard_each_row_came_from():
    cs = cores(2, [300, 300], sampler="prioritized")
    replay = sharded(cs)
    batch = replay.sample(SampleRequest(128))
    replay.send_priorities(wire.PriorityUpdate(
        index=batch.index, is_demo=batch.is_demo, priority=np.full(len(batch.index), 7.0, np.float32)))
    for i, core in enumerate(cs):
        mine = batch.obs[:, 1] == i
        assert core.priority_updates == 1 and core.rejected == {}
        leaves = core.demo.size + (batch.index[mine] // 2) % core.online.capacity
        expected = (7.0 + core.cfg.priority_eps) ** core.cfg.priority_alpha
        assert np.allclose(core.selector.priority_of(leaves), expected)


def test_a_refusing_shard_leaves_its_rows_to_the_others_and_the_cut_is_counted():
    cs = cores(2, [500, 0], min_size=200)  # shard 1 has nothing yet: not ready
    replay = sharded(cs)
    batch = replay.sample(SampleRequest(64, 4))  # 128 rows each: shard 0 serves 2 whole batches
    assert batch.num_batches == 2 and len(batch.action) == 128 and np.all(batch.obs[:, 1] == 0)
    assert replay.partial_requests == 1 and replay.discarded_rows == 0
    # Shard 1 is still unheard of (its share: the mean of the known ones, half); shard 0's 90 rows
    # make one whole batch of 60, and the 30 rows beyond it are cut and counted.
    batch = replay.sample(SampleRequest(60, 3))
    assert batch.num_batches == 1 and len(batch.action) == 60 and replay.discarded_rows == 30
    only = sharded(cores(2, [0, 0], min_size=200))
    refused = only.sample(SampleRequest(32))
    assert isinstance(refused, wire.WireError) and refused.reason == "rate_limited"


def test_sync_requests_need_every_shard_and_ask_each_for_its_own_workers():
    cs = cores(2, [100, 100])
    replay = sharded(cs)
    ok = replay.sample(SampleRequest(32, 1, min_version=0, actors=("w0", "w1")))
    assert isinstance(ok, wire.SampledBatch)
    waiting = replay.sample(SampleRequest(32, 1, min_version=1, actors=("w0", "w1")))
    assert isinstance(waiting, wire.WireError) and waiting.reason == "not_ready"


def test_control_and_stats_reach_every_shard():
    cs = cores(2, [120, 80], demo_mode="rehearsal")
    replay = sharded(cs)
    assert replay.set_phase(2) is True
    assert [c.phase for c in cs] == [2, 2]
    assert replay.set_phase(1) is False  # phases only move forward
    stats = replay.replay_stats()
    assert stats["tables"]["online"]["inserted"] == 0  # rehearsal's phase 1 stored nothing: it was phase 1
    assert stats["actors_total"]["count"] == 2 and stats["actors_total"]["items"] == 200
    assert [s["actors"] for s in stats["shards"]] == [1, 1]
    assert stats["sharded_sampling"] == {"discarded_rows": 0, "partial_requests": 0}


def test_merged_stats_sum_counters_and_keep_extremes():
    a = {"mode": "retention", "phase": 0, "tables": {"online": {"size": 10, "capacity": 50, "inserted": 12, "bytes": 4},
                                                     "demo": {"size": 5, "held": 9, "sha256": "x", "bytes": 3}},
         "demo_in_buffer": 5, "rejected": {"bad_key": 1}, "requests": {"served": 2},
         "actors_total": {"count": 1, "env_steps": 100, "lost_batches": 1, "min_version": 3, "max_version": 4},
         "rates": {"inserts_per_s": 10.0, "samples_per_s": 30.0}, "demo_share_recent_samples": 0.2,
         "actors": {"w0": {"batches": 1}}}
    b = {**a, "phase": 1, "demo_in_buffer": 5, "rejected": {"bad_key": 2, "too_big": 1},
         "actors_total": {"count": 2, "env_steps": 50, "lost_batches": 0, "min_version": 1, "max_version": 9},
         "rates": {"inserts_per_s": 5.0, "samples_per_s": 10.0}, "demo_share_recent_samples": 0.0,
         "actors": {"w1": {"batches": 2}}}
    m = merge_replay_stats([a, b])
    assert m["tables"]["online"] == {"size": 20, "capacity": 100, "inserted": 24, "bytes": 8}
    assert m["tables"]["demo"]["held"] == 9 and m["tables"]["demo"]["size"] == 10
    assert m["demo_share_buffer"] == pytest.approx(10 / 30)
    assert m["rejected"] == {"bad_key": 3, "too_big": 1} and m["requests"] == {"served": 4}
    assert m["actors_total"]["env_steps"] == 150 and m["actors_total"]["lost_batches"] == 1
    assert (m["actors_total"]["min_version"], m["actors_total"]["max_version"]) == (1, 9)
    assert m["phase"] == 0 and sorted(m["actors"]) == ["w0", "w1"]
    assert m["demo_share_recent_samples"] == pytest.approx(0.15)  # weighted by samples/s: (0.2*30) / 40
    assert merge_replay_stats([a]) is a


# --------------------------------------------------------------------------- whole runs, in-process

FAST = {"env.scenario": "lka", "actor.send_every": 50, "learner.hidden": "32,32", "learner.batch_size": 32,
        "learner.publish_every": 5, "replay.min_size": 100, "replay.samples_per_insert": 4,
        "replay.spi_tolerance": 512, "replay.shards": 2}


@pytest.mark.parametrize("sampler", ["uniform", "prioritized"])
def test_inprocess_run_on_two_shards(tmp_path, sampler):
    cfg = load_run_config(overrides={**FAST, "replay.sampler": sampler, "train.env_steps": 2000,
                                     "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    replay = result["replay"]
    assert [s["inserted"] for s in replay["shards"]] == [1000, 1000]  # w0 -> shard 0, w1 -> shard 1
    assert replay["tables"]["online"]["inserted"] == 2000 and replay["rejected"] == {}
    assert replay["actors_total"]["lost_batches"] == 0
    # Every sampled row trained the learner but for the replies in flight at the end, counted ...
    assert result["updates"] * 32 + result["learner"]["sample_rows_unused"] <= replay["sampled_rows"]
    # ... and each shard's ratio held (4 per insert after its min_size, plus its tolerance).
    for shard in replay["shards"]:
        assert shard["rate_limiter"]["samples_per_insert"] == 4.0
    assert replay["sampled_rows"] <= (2000 - 100) * 4 + 2 * 512
    if sampler == "prioritized":
        # One priority message per shard and reply trained on (2 replies in flight at the end made none).
        served = replay["requests"]["served"]
        assert 0 < served - 2 * 2 <= replay["sampler"]["priority_updates"] <= served


def test_every_shard_is_asked_before_any_reply_is_awaited():
    """The sample path asks all shards from the calling thread first, then collects: the replies
    are in flight together, and no pool thread is woken per request."""
    cs = cores(3, [300, 300, 300])
    events: list[tuple[str, int]] = []
    threads: set[str] = set()

    class Recorded(InProcessReplay):
        def __init__(self, core, i):
            super().__init__(core, SCHEMA)
            self.i = i

        def request_sample(self, req):
            events.append(("ask", self.i))
            threads.add(threading.current_thread().name)
            batch = self.sample(req)

            def reply():
                events.append(("wait", self.i))
                return batch
            return reply

    replay = ShardedReplay([Recorded(c, i) for i, c in enumerate(cs)], seed=0)
    batch = replay.sample(wire.SampleRequest(96))
    assert isinstance(batch, wire.SampledBatch) and len(batch.action) == 96
    assert events == [("ask", 0), ("ask", 1), ("ask", 2), ("wait", 0), ("wait", 1), ("wait", 2)]
    assert threads == {threading.current_thread().name}
