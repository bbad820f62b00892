"""The next sample request in flight while the current batch trains (the learner's async mode).

Without it the learner alternates: ask the replay server, wait for the reply (a round trip
through the router and a decode of ~175 KB per 256 rows), then update. Measured inside a running
system, the learner waited 18 % of its time on sample replies (``learner_sample_wait_share`` in
`laneshift bench run`'s ``waits``). ``Prefetcher`` runs the
requests on a thread of their own, one request ahead of the updates (``depth`` replies queued):
zenoh's query and numpy's decode release the GIL, so the round trip overlaps torch's update.

A refusal (rate limiter, not ready) or no answer is waited out on the thread
(``batches.retry_delay``), so the updates never wait twice. At the end of
a run the replies taken but not trained on are counted (``unused_rows``): they were sampled (the
replay server counted them) but made no update.

Room: learner (component). May import: the contract and laneshift.learner; never another component.
"""

from __future__ import annotations

import queue
import threading
from typing import Callable

from laneshift import wire

from .batches import Sample, sample_or_wait


class Prefetcher:
    """Keeps up to ``depth`` sampled batches ready; ``take(timeout)`` returns one or None."""

    def __init__(self, sample: Sample, request: Callable[[], wire.SampleRequest], stop: threading.Event,
                 depth: int = 1):
        self._sample, self._request, self._stop = sample, request, stop
        self._ready: queue.Queue[wire.SampledBatch] = queue.Queue(maxsize=max(1, depth))
        self._closed = threading.Event()
        self.refusals = 0  # replies that were a refusal or no answer (waited out on the thread)
        self._held_rows = 0  # rows of a reply the thread still held when it was closed
        self._thread = threading.Thread(target=self._loop, name="learner-prefetch", daemon=True)
        self._thread.start()

    def _done(self) -> bool:
        return self._closed.is_set() or self._stop.is_set()

    def _loop(self) -> None:
        while not self._done():
            result = sample_or_wait(self._sample, self._request(), self._closed.wait)
            if result is None:
                self.refusals += 1
                continue
            while True:
                if self._done():
                    self._held_rows += len(result.action)
                    return
                try:
                    self._ready.put(result, timeout=0.1)
                    break
                except queue.Full:
                    continue

    def take(self, timeout: float) -> wire.SampledBatch | None:
        try:
            return self._ready.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self, timeout: float = 10.0) -> int:
        """Stop the thread; returns the rows it had sampled that no update used."""
        self._closed.set()
        self._thread.join(timeout)
        unused = self._held_rows
        while True:
            try:
                batch = self._ready.get_nowait()
            except queue.Empty:
                return unused
            unused += len(batch.action)
