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
(``learner/process.py``).

Room: learner (component). May import: the standard library and torch.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import torch


def _threads_of_this_process() -> list[int]:
    try:
        return [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:  # no /proc: this thread only
        return [0]


def _masks() -> dict[int, set[int]]:
    """Each thread's CPU mask now (a thread that ended meanwhile is left out)."""
    masks = {}
    for tid in _threads_of_this_process():
        try:
            masks[tid] = os.sched_getaffinity(tid)
        except OSError:
            pass
    return masks


def _set_affinity(cpus: set[int], masks: dict[int, set[int]] | None = None) -> None:
    """Every thread of this process on ``cpus``, or, for a thread in ``masks``, back on its own
    mask (``sched_setaffinity`` moves one thread); the kernel keeps each mask within the CPUs the
    process's cgroup allows. A thread that ended meanwhile, or one that refuses, is skipped."""
    for tid in _threads_of_this_process():
        try:
            os.sched_setaffinity(tid, (masks or {}).get(tid, cpus))
        except OSError:
            pass


def node_cpus() -> set[int]:
    """The CPUs this process could run on if it were not pinned: the machine's CPUs within its
    cgroup's cpuset (read from /sys where cgroup v2 says; otherwise all of ``os.cpu_count()``, which
    ``sched_setaffinity`` narrows to the allowed ones)."""
    try:
        text = Path("/sys/fs/cgroup/cpuset.cpus.effective").read_text().strip()
        cpus: set[int] = set()
        for part in text.split(","):
            lo, _, hi = part.partition("-")
            cpus.update(range(int(lo), int(hi or lo) + 1))
        if cpus:
            return cpus
    except (OSError, ValueError):
        pass
    return set(range(os.cpu_count() or 1))


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
    masks, mask_before, threads_before = _masks(), os.sched_getaffinity(0), torch.get_num_threads()
    _set_affinity(node_cpus())
    wide = os.sched_getaffinity(0)
    n = threads or len(wide)
    if n <= threads_before:
        _set_affinity(mask_before, masks)
        yield None
        return
    torch.set_num_threads(n)  # the intra-op threads start on the widened mask of this thread
    try:
        yield f"phase 1 on CPUs {sorted(wide)} with {n} torch threads (learner.phase1_threads; then " \
              f"{threads_before} on CPUs {sorted(mask_before)})"
    finally:
        torch.set_num_threads(threads_before)
        _set_affinity(mask_before, masks)
