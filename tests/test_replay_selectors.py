"""``replay_server.selectors``: the two row pickers the replay core holds, on their own.
Room: tests, unit. May import: numpy, pytest, laneshift.replay_server.selectors.
"""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.replay_server.selectors import PrioritizedSelector, UniformSelector


def test_uniform_draws_every_live_row_and_only_those():
    rng = np.random.default_rng(0)
    d = UniformSelector().draw(rng, 20_000, n_demo=3, online_tail=6, online_size=4, online_capacity=8)
    assert set(d.demo_rows.tolist()) == {0, 1, 2}
    assert set(d.online_rows.tolist()) == {6, 7, 0, 1}  # from the ring's tail on, wrapping
    assert d.is_demo.mean() == pytest.approx(3 / 7, abs=0.02) and (d.weight == 1).all()


@pytest.mark.parametrize("tail,size,live", [
    (0, 5, {0, 1, 2, 3, 4}),  # not yet wrapped
    (13, 8, set(range(8))),  # full: every row, whatever the tail
    (6, 4, {6, 7, 0, 1}),  # a frame table's tail ahead of a full ring's, wrapping
    (16, 3, {0, 1, 2}),  # the same at a multiple of the capacity
])
def test_uniform_online_only_draws_the_live_rows(tail, size, live):
    rng = np.random.default_rng(1)
    selector = UniformSelector()
    d = selector.draw(rng, 5_000, n_demo=0, online_tail=tail, online_size=size, online_capacity=8)
    assert set(d.online_rows.tolist()) == live and len(d.demo_rows) == 0
    again = selector.draw(rng, 5_000, n_demo=0, online_tail=tail, online_size=size, online_capacity=8)
    # The all-False mask and the unit weights are shared between draws, so nobody may write them.
    assert again.is_demo is d.is_demo and again.weight is d.weight
    assert not d.is_demo.flags.writeable and not d.weight.flags.writeable
    assert not d.is_demo.any() and (d.weight == 1).all()


def test_prioritized_draws_by_mass_and_weights_the_rare_rows_up():
    s = PrioritizedSelector(demo_size=2, online_capacity=4, alpha=1.0, beta=1.0, demo_bonus=1.0)
    s.inserted(np.array([0, 1]))  # new items at the highest priority seen (1.0)
    assert s.priority_of(np.arange(6)).tolist() == [2.0, 2.0, 1.0, 1.0, 0.0, 0.0]  # demo leaves: 1 + bonus
    s.update(np.array([0]), np.array([9.0]), np.array([1]), np.array([3.0]))
    assert s.max_priority == 9.0 and s.priority_of(np.array([0, 3])).tolist() == [9.0, 3.0]
    d = s.draw(np.random.default_rng(0), 20_000, n_demo=2, online_tail=0, online_size=2, online_capacity=4)
    assert (d.online_rows < 2).all()  # rows 2, 3 hold nothing
    assert np.mean(d.demo_rows == 0) * d.is_demo.mean() == pytest.approx(9 / 15, abs=0.02)
    assert d.weight.max() == pytest.approx(1.0) and d.weight[~d.is_demo].min() > d.weight.min()


def test_dropped_rows_and_demos_off_carry_no_mass():
    s = PrioritizedSelector(demo_size=2, online_capacity=4, alpha=0.6, beta=0.4, demo_bonus=1.0)
    s.inserted(np.arange(4))
    s.dropped(np.array([1, 2]))
    s.demos_off()
    assert s.priority_of(np.arange(6)).tolist() == [0.0, 0.0, 1.0, 0.0, 0.0, 1.0]
    d = s.draw(np.random.default_rng(1), 1000, n_demo=0, online_tail=0, online_size=4, online_capacity=4)
    assert not d.is_demo.any() and set(d.online_rows.tolist()) == {0, 3}
