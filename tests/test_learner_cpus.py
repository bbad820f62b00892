"""``learner.cpus.phase1_cpus``: phase 1 lifts the learner's pin and widens torch's threads, then puts
back every thread's own mask and the thread count; a GPU learner and ``learner.phase1_threads=1``
change nothing. Real affinity calls on this process, restored by each test. ``ThreadChooser`` (phase
1's thread count timed as it goes) on a made-up clock: the faster count kept, timed again each round.

Room: tests, unit. May import: laneshift (any floor), pytest, torch and the standard library."""

from __future__ import annotations

import os
import threading

import pytest
import torch

from laneshift.config import ConfigError, LearnerConfig
from laneshift.cpus import node_cpus, set_thread_masks, thread_masks
from laneshift.learner.cpus import phase1_cpus

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(node_cpus() & os.sched_getaffinity(0)) < 2,
                                reason="needs CPU affinity and two CPUs")


@pytest.fixture()
def pinned_to_one_cpu():
    """This process on one CPU with one torch thread, as a pinned learner is; restored afterwards."""
    mask, threads = os.sched_getaffinity(0), torch.get_num_threads()
    # laneshift.cpus' walk over the threads: one that ends between the listing and the move (torch's,
    # Ray's) is skipped, where a walk of its own here failed with ProcessLookupError.
    masks = thread_masks()
    first = min(mask)
    assert set_thread_masks({first})
    torch.set_num_threads(1)
    yield first
    torch.set_num_threads(threads)
    set_thread_masks(mask, masks=masks)


def test_phase1_uses_every_cpu_then_goes_back(pinned_to_one_cpu):
    wide = node_cpus()
    with phase1_cpus(0, torch.device("cpu")) as line:
        assert os.sched_getaffinity(0) == wide & os.sched_getaffinity(0) and len(os.sched_getaffinity(0)) >= 2
        assert torch.get_num_threads() == len(os.sched_getaffinity(0))
        assert line is not None and "phase 1 on CPUs" in line and "learner.phase1_threads" in line
        torch.ones(512, 512) @ torch.ones(512, 512)  # start torch's threads inside the block
    assert os.sched_getaffinity(0) == {pinned_to_one_cpu}
    assert torch.get_num_threads() == 1


def test_an_explicit_thread_count_is_kept(pinned_to_one_cpu):
    with phase1_cpus(2, torch.device("cpu")) as line:
        assert torch.get_num_threads() == 2 and line is not None
    assert torch.get_num_threads() == 1 and os.sched_getaffinity(0) == {pinned_to_one_cpu}


def test_other_threads_get_their_own_masks_back(pinned_to_one_cpu):
    """In-process mode the workers are threads of the learner's process: each keeps its own mask."""
    other = max(os.sched_getaffinity(0) | node_cpus())
    ready, done, seen = threading.Event(), threading.Event(), {}

    def worker():
        os.sched_setaffinity(0, {other})
        ready.set()
        done.wait(5)
        seen["after"] = os.sched_getaffinity(0)

    t = threading.Thread(target=worker)
    t.start()
    assert ready.wait(5)
    with phase1_cpus(0, torch.device("cpu")):
        pass
    done.set()
    t.join(5)
    assert seen["after"] == {other}


@pytest.mark.parametrize("threads, device", [(1, "cpu"), (0, "cuda")])
def test_nothing_changes_for_one_thread_or_a_gpu(pinned_to_one_cpu, threads, device):
    with phase1_cpus(threads, torch.device(device)) as line:
        assert line is None
        assert os.sched_getaffinity(0) == {pinned_to_one_cpu} and torch.get_num_threads() == 1
    assert os.sched_getaffinity(0) == {pinned_to_one_cpu}


@pytest.mark.parametrize("bad", [-1, True, 1.5])
def test_config_refuses_a_bad_thread_count(bad):
    with pytest.raises(ConfigError, match="learner.phase1_threads"):
        LearnerConfig(phase1_threads=bad)


def _drive(chooser, speed, until: float, step: float = 0.1, start: tuple[float, int] = (0.0, 0)) -> list:
    """Ticks every ``step`` s, the updates growing at ``speed(count, now)`` a second; the switches asked for."""
    now, updates, asked = start[0], start[1], []
    while now < until:
        now += step
        updates += round(speed(chooser.current, now) * step)
        count = chooser.tick(updates, now)
        if count is not None:
            asked.append((round(now, 1), count))
    return asked


def test_the_chooser_keeps_every_cpu_on_a_quiet_machine_and_one_thread_beside_a_busy_process():
    from laneshift.learner.cpus import ThreadChooser

    chooser = ThreadChooser((2, 1), window_s=3.0, every_s=30.0)
    quiet = {2: 150.0, 1: 130.0}
    asked = _drive(chooser, lambda c, now: quiet[c], until=7.0)
    # Two timed first (its window from the first tick), then one, then two kept.
    assert [c for _, c in asked] == [1, 2] and chooser.chosen == 2
    assert chooser.rates == pytest.approx({2: 150.0, 1: 130.0}, rel=0.05)
    assert chooser.summary().startswith("2 threads 15") and "1 thread 13" in chooser.summary()
    # Another process starts on the CPUs: at the next round one thread wins and is kept.
    busy = {2: 9.0, 1: 80.0}
    asked = _drive(chooser, lambda c, now: busy[c], until=45.0, start=(7.0, 1000))
    assert asked[-1][1] == 1 and chooser.chosen == 1 and chooser.current == 1
    assert 36.0 < asked[-1][0] < 45.0  # after 30 s untimed and the two windows
    # It ends: two threads again after the following round.
    _drive(chooser, lambda c, now: quiet[c], until=90.0, start=(45.0, 5000))
    assert chooser.chosen == 2 and chooser.current == 2


def test_the_slower_count_costs_at_most_one_window_a_round():
    from laneshift.learner.cpus import ThreadChooser

    chooser = ThreadChooser((2, 1), window_s=3.0, every_s=30.0)
    speed = {2: 10.0, 1: 100.0}
    time_on = {1: 0.0, 2: 0.0}

    def rate(count, now):
        time_on[count] += 0.1
        return speed[count]

    _drive(chooser, rate, until=600.0)
    assert time_on[2] / 600.0 < 3.0 / 33.0 + 0.02  # one window of 3 s a round of 36 s (the first round too)


@pytest.mark.parametrize("counts, window, every", [((2,), 3.0, 30.0), ((2, 2), 3.0, 30.0), ((2, 0), 3.0, 30.0),
                                                   ((2, 1), 0.0, 30.0), ((2, 1), 3.0, -1.0)])
def test_the_chooser_refuses_what_it_cannot_time(counts, window, every):
    from laneshift.learner.cpus import ThreadChooser

    with pytest.raises(ValueError, match="ThreadChooser"):
        ThreadChooser(counts, window_s=window, every_s=every)
