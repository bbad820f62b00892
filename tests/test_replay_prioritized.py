"""Prioritized sampling: sum tree, importance weights, priority updates, DQfD demo bonus.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.storage import DemoTable
from laneshift.replay_server.sum_tree import SumTree

SCHEMA = wire.TransitionSchema((2,), "float32", 4)


def batch(seq: int, n: int = 10) -> bytes:
    obs = np.full((n, 2), seq, np.float32)
    return wire.encode_transitions(wire.TransitionBatch.from_arrays(
        actor="w0", seq=seq, weights_version=0, phase=0, env_steps=n * (seq + 1), obs=obs, action=np.zeros(n),
        reward=np.zeros(n, np.float32), next_obs=obs, terminated=np.zeros(n), truncated=np.zeros(n)))


def demo_table(n: int) -> DemoTable:
    obs = np.full((n, 2), -1, np.float32)
    return DemoTable(obs, np.zeros(n, np.int64), np.zeros(n, np.float32), obs.copy(), np.zeros(n, np.uint8), "s", {})


def test_sum_tree_matches_a_loop_and_samples_proportionally():
    rng = np.random.default_rng(0)
    tree = SumTree(37)
    values = np.zeros(37)
    for _ in range(50):
        idx = rng.integers(0, 37, size=5)
        val = rng.random(5) * (rng.random(5) > 0.3)
        tree.set(idx, val)
        for i, v in zip(idx, val):
            values[i] = v
        assert tree.total == pytest.approx(values.sum())
    counts = np.bincount(tree.sample(rng, 400_000), minlength=37) / 400_000
    assert np.abs(counts - values / values.sum()).max() < 0.004
    assert (counts[values == 0] == 0).all()
    with pytest.raises(ValueError):
        tree.set(np.array([0]), np.array([np.nan]))


def test_new_items_get_the_max_priority_and_updates_move_mass():
    core = ReplayCore(ReplayConfig(capacity=100, min_size=1, sampler="prioritized", priority_alpha=1.0,
                                   priority_eps=1e-6, samples_per_insert=0), SCHEMA)
    for seq in range(5):
        core.ingest(batch(seq))
    b = core.sample(wire.SampleRequest(50))
    assert b.info["prioritized"] and np.allclose(b.weight, 1.0)  # equal priorities: uniform, weight 1
    # Give item key 7 a huge priority: it should dominate the next batch, with the smallest weight.
    core.update_priorities(wire.PriorityUpdate(index=np.array([7]), is_demo=np.array([0], np.uint8),
                                               priority=np.array([1000.0], np.float32)))
    b = core.sample(wire.SampleRequest(1000))
    share = (b.index == 7).mean()
    assert share == pytest.approx(1000 / (1000 + 49), abs=0.03)
    assert b.weight[b.index == 7].max() < b.weight[b.index != 7].min() <= 1.0
    # The max priority now goes to new items.
    core.ingest(batch(5))
    assert core.selector.priority_of(np.array([55]))[0] == pytest.approx(1000.0, rel=1e-3)


def test_updates_for_evicted_items_are_ignored():
    core = ReplayCore(ReplayConfig(capacity=20, min_size=1, sampler="prioritized", samples_per_insert=0), SCHEMA)
    core.ingest(batch(0))
    core.ingest(batch(1))
    old_key = 3
    core.ingest(batch(2))  # keys 20..29 overwrite rows 0..9, so key 3 is gone
    assert core.update_priorities(wire.PriorityUpdate(np.array([old_key, 25]), np.zeros(2, np.uint8),
                                                      np.array([5.0, 5.0], np.float32))) == 1


def test_demo_bonus_and_rehearsal_phases():
    cfg = ReplayConfig(capacity=100, min_size=1, demo_mode="rehearsal", sampler="prioritized",
                       priority_alpha=1.0, priority_eps=1e-6, demo_priority_bonus=1.0, samples_per_insert=0)
    core = ReplayCore(cfg, SCHEMA, demo_table(10))
    b = core.sample(wire.SampleRequest(64))
    assert b.is_demo.all()
    core.update_priorities(wire.PriorityUpdate(np.array([0, 1]), np.ones(2, np.uint8), np.array([0.0, 3.0], np.float32)))
    assert core.selector.priority_of(np.array([0, 1])).tolist() == pytest.approx([1.0, 4.0])  # |td| + eps + bonus
    core.set_phase(2)
    assert core.selector.priority_of(np.arange(10)).sum() == 0  # ordinary replay: demos no longer drawn
    core.ingest(batch(0))
    assert not core.sample(wire.SampleRequest(64)).is_demo.any()
    assert core.update_priorities(wire.PriorityUpdate(np.array([0]), np.ones(1, np.uint8),
                                                      np.array([9.0], np.float32))) == 0


def test_priorities_message_round_trip_and_rejections():
    up = wire.PriorityUpdate(np.array([1, 2]), np.array([0, 1], np.uint8), np.array([0.5, 2.0], np.float32))
    back = wire.decode_priorities(wire.encode_priorities(up))
    assert back.index.tolist() == [1, 2] and back.priority.tolist() == [0.5, 2.0]
    core = ReplayCore(ReplayConfig(capacity=10, min_size=1, sampler="prioritized"), SCHEMA)
    bad = wire.encode_priorities(wire.PriorityUpdate(np.array([1]), np.array([0], np.uint8),
                                                     np.array([np.nan], np.float32)))
    assert core.handle_priorities(bad) == "priorities:non_finite"
    assert core.handle_priorities(b"junk") == "priorities:truncated"
    assert core.stats()["rejected"] == {"priorities:non_finite": 1, "priorities:truncated": 1}
