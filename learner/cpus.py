"""Phase 1 on every CPU: the learner's pre-training (``dqfd`` and ``rehearsal`` phase 1, updates on
the demo shard alone) runs while every actor waits, so the CPUs the actors will use stand idle.
``phase1_cpus`` lifts the learner's pin (``deploy.learner_core``) and gives torch one thread per
CPU the process may use for that phase, then puts both back as they were.

Why it pays: on the 2-core machine a run pins the learner to one CPU and its workers to the other;
in phase 1 the workers' CPU sat idle (``top``: 47 % idle for the 5 minutes of an ``allroads`` run's
20,000 pre-training updates); with it, phase 1 of a run made 1.13x the updates a second with
256 x 256 units and 1.41x with 512 x 512 (`tools/bench/scripts/phase1_threads.py`,
docs/performance-log.md). Why only phase 1: in phase 2 the workers, the replay server and the
router use the other CPUs, and a second learner thread there made runs slower
(``learner/process.py``). Where another process keeps those CPUs busy in phase 1, one thread per CPU
is several times slower than one: ``ThreadChooser`` times both as phase 1 goes and keeps the faster.

Room: learner (component). May import: the standard library, torch and the contract
(``laneshift.cpus`` moves the threads).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

from laneshift.config import LearnerConfig
from laneshift.cpus import has_bf16_instructions, node_cpus, set_thread_masks, thread_masks


@contextmanager
def phase1_cpus(threads: int, device: torch.device) -> Iterator[str | None]:
    """Within the block: this process on every CPU it may use and ``threads`` torch threads (0:
    one per such CPU). Yields a line for the log, or None where nothing changes (a GPU learner,
    one CPU, ``threads`` no more than now). Restores the affinity and thread count on the way out."""
    if device.type != "cpu" or not hasattr(os, "sched_getaffinity"):
        yield None
        return
    # Each thread goes back to its own mask (in-process mode the workers' threads share the
    # process); threads started within the block (torch's) get this thread's.
    masks, mask_before, threads_before = thread_masks(), os.sched_getaffinity(0), torch.get_num_threads()
    set_thread_masks(node_cpus())
    wide = os.sched_getaffinity(0)
    n = threads or len(wide)
    if n <= threads_before:
        set_thread_masks(mask_before, masks=masks)
        yield None
        return
    torch.set_num_threads(n)  # the intra-op threads start on the widened mask of this thread
    try:
        yield f"phase 1 on CPUs {sorted(wide)} with {n} torch threads (learner.phase1_threads; then " \
              f"{threads_before} on CPUs {sorted(mask_before)})"
    finally:
        torch.set_num_threads(threads_before)
        set_thread_masks(mask_before, masks=masks)


class ThreadChooser:
    """Phase 1's torch threads chosen by the updates a second each count makes here and now
    (``learner.phase1_threads=0``): one per CPU, or one.

    Why measured, not fixed: one thread per CPU makes phase 1 1.13x faster on a quiet machine
    (256 x 256 units, the module doc), but when another process keeps a CPU busy, a thread of
    torch's loses its turn on it and the other waits for it at each of the small ops' joins:
    beside one busy process, phase 1 of a merge run made 3.8 updates a second on two threads and
    59.1 on one (`tools/bench/scripts/phase1_threads.py --busy 1`, docs/performance-log.md,
    2026-11-29). So each count is timed over ``window_s`` in turn, the
    faster one kept for ``every_s``, and timed again then, since the other process may end or start.
    At most ``window_s`` in ``every_s + 2 * window_s`` goes to the slower count.

    ``tick(updates, now)`` after each batch of updates: the thread count to set now, or None.
    """

    def __init__(self, counts: tuple[int, ...], window_s: float = 3.0, every_s: float = 30.0) -> None:
        if len(set(counts)) < 2 or min(counts) < 1:
            raise ValueError(f"ThreadChooser: at least two different counts >= 1, got {counts}")
        if window_s <= 0 or every_s < 0:
            raise ValueError(f"ThreadChooser: window_s > 0 and every_s >= 0, got {window_s}, {every_s}")
        self.window_s, self.every_s = window_s, every_s
        self.current = counts[0]  # the count set when phase 1 starts (phase1_cpus')
        self.rates: dict[int, float] = {}  # updates a second of each count, the last time it was timed
        self._trials = list(counts)  # the counts still to time in this round, the one running first
        self._start: tuple[float, int] | None = None  # (time, updates) where the running window began
        self._until = 0.0  # the chosen count runs untimed until then
        self.chosen: int | None = None  # the faster count of the last round of timings

    def tick(self, updates: int, now: float) -> int | None:
        if not self._trials:  # the chosen count's untimed stretch
            if now < self._until:
                return None
            # The other counts first, the chosen one last: it is running now, so its window starts at once.
            self._trials = [c for c in self.rates if c != self.current] + [self.current]
            return self._begin(updates, now)
        if self._start is None:
            self._start = (now, updates)
            return None
        began, done = self._start
        if now - began < self.window_s:
            return None
        self.rates[self._trials.pop(0)] = (updates - done) / (now - began)
        if self._trials:
            return self._begin(updates, now)
        self._until = now + self.every_s
        self.chosen = max(self.rates, key=lambda c: (self.rates[c], c))
        return self._switch(self.chosen)

    def _begin(self, updates: int, now: float) -> int | None:
        # A window starts at the first tick on its count: the updates already in flight at a switch
        # (a batch, the prefetched requests' decode) are the previous count's.
        self._start = (now, updates) if self._trials[0] == self.current else None
        return self._switch(self._trials[0])

    def _switch(self, count: int) -> int | None:
        if count == self.current:
            return None
        self.current = count
        return count

    def summary(self) -> str:
        """The last timings, for the log: ``2 threads 150.2/s, 1 thread 133.0/s``."""
        return ", ".join(f"{c} thread{'s' if c > 1 else ''} {r:.1f}/s" for c, r in sorted(self.rates.items(),
                                                                                        reverse=True))


def bf16_warning(cfg: LearnerConfig, device: torch.device) -> str | None:
    """One line for the log where ``learner.cnn_precision`` or ``learner.mlp_precision`` asks a CPU
    learner for bfloat16 and /proc/cpuinfo says the CPU has no bfloat16 instructions; None otherwise.
    A warning, not a refusal: the config is valid, the machine that runs the learner (in a cluster,
    not the one that checked the config) makes it slow."""
    asked = [f"learner.{name}=bf16" for name in ("cnn_precision", "mlp_precision") if getattr(cfg, name) == "bf16"]
    if not asked or device.type != "cpu" or has_bf16_instructions() is not False:
        return None
    return (f"{' and '.join(asked)} on a CPU without bfloat16 instructions (no avx512_bf16, amx_bf16 or bf16 in "
            f"/proc/cpuinfo): torch emulates them, several times slower than fp32 (SmallCNN at batch 32: 2.0 "
            f"against 23.4 updates/s on an AMD EPYC without them); fp32 is the faster choice here")
