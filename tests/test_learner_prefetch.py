"""``learner.prefetch.Prefetcher``: the next sample request runs while a batch trains; refusals
are waited out on its thread as long as the replay server asked; rows sampled but never trained
on are counted at the end.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import threading
import time

import numpy as np

from laneshift import wire
from laneshift.learner.prefetch import Prefetcher


def batch(tag: int, rows: int = 8) -> wire.SampledBatch:
    z = np.zeros(rows, np.float32)
    return wire.SampledBatch(obs=np.full((rows, 2), tag, np.float32), action=np.zeros(rows, np.int64), reward=z,
                             next_obs=np.zeros((rows, 2), np.float32), terminated=np.zeros(rows, np.uint8),
                             steps=np.ones(rows, np.uint8), is_demo=np.zeros(rows, np.uint8),
                             index=np.arange(rows, dtype=np.int64), weight=np.ones(rows, np.float32))


def refusal(ms: int) -> wire.WireError:
    err = wire.WireError("rate_limited", "test")
    err.retry_after_ms = ms  # type: ignore[attr-defined]
    return err


def test_batches_come_in_order_and_refusals_are_waited_out_on_the_thread():
    replies = [refusal(50), None, batch(1), batch(2), batch(3)]
    asked: list[float] = []

    def sample(req: wire.SampleRequest):
        asked.append(time.monotonic())
        return replies.pop(0) if replies else batch(99)

    pre = Prefetcher(sample, lambda: wire.SampleRequest(8), threading.Event(), depth=1)
    got = [pre.take(timeout=5.0) for _ in range(3)]
    assert [int(b.obs[0, 0]) for b in got] == [1, 2, 3]
    assert pre.refusals == 2
    assert asked[1] - asked[0] >= 0.045 and asked[2] - asked[1] >= 0.09  # 50 ms asked; 0.1 s for no answer
    unused = pre.close()
    assert unused % 8 == 0 and 0 < unused <= 2 * 8  # one queued, maybe one more held by the thread


def test_the_run_stop_ends_the_thread_and_take_times_out():
    stop = threading.Event()
    pre = Prefetcher(lambda req: None, lambda: wire.SampleRequest(8), stop)
    assert pre.take(timeout=0.05) is None
    stop.set()
    assert pre.close(timeout=2.0) == 0
    assert not pre._thread.is_alive()
