"""Which CPUs a process's threads run on: the one place that reads and sets per-thread CPU masks,
for the two that move threads (``deploy.pinning``, which pins a run's processes, and
``learner.cpus``, which lifts the learner's pin for phase 1).

Why per thread: ``os.sched_setaffinity(pid)`` sets the mask of one thread only, so moving a
process that already runs threads (torch's, Ray's, zenoh's) means walking ``/proc/<pid>/task``.

Room: the contract (every process may use it). May import: the standard library only.
"""

from __future__ import annotations

import os
from pathlib import Path


def thread_ids(pid: int | None = None) -> list[int]:
    """The thread ids of ``pid`` (None: this process); [] if it is gone. Without /proc, for this
    process: [0], the calling thread, which is what ``sched_setaffinity(0)`` moves."""
    try:
        return [int(t) for t in os.listdir(f"/proc/{pid or 'self'}/task")]
    except OSError:
        return [0] if pid is None else []


def thread_masks(pid: int | None = None) -> dict[int, set[int]]:
    """Each thread's CPU mask now (a thread that ended meanwhile is left out)."""
    masks = {}
    for tid in thread_ids(pid):
        try:
            masks[tid] = os.sched_getaffinity(tid)
        except OSError:
            pass
    return masks


def set_thread_masks(cpus: set[int], pid: int | None = None, masks: dict[int, set[int]] | None = None) -> bool:
    """Every thread of ``pid`` (None: this process) on ``cpus``, or, for a thread in ``masks``, back
    on its own mask; the kernel keeps each mask within the CPUs the cgroup allows. A thread that
    ended meanwhile, or one that refuses, is skipped. False if no thread was moved (the process is
    gone or refuses)."""
    moved = False
    for tid in thread_ids(pid):
        try:
            os.sched_setaffinity(tid, (masks or {}).get(tid, cpus))
            moved = True
        except OSError:
            pass
    return moved


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


#: The /proc/cpuinfo flags of CPUs that multiply bfloat16 in hardware: x86 AVX512-BF16 or AMX-BF16
#: (``flags``), Arm's BF16 extension (``Features``).
BF16_FLAGS = frozenset({"avx512_bf16", "amx_bf16", "bf16"})


def has_bf16_instructions(cpuinfo: str | None = None) -> bool | None:
    """Whether this machine's CPUs have bfloat16 instructions, from ``/proc/cpuinfo`` (or the text
    given); None where that cannot be told (no /proc/cpuinfo, no flags line). Without them torch
    emulates bfloat16 in software: on an AMD EPYC without them SmallCNN's update at batch 32 ran at
    2.0 against 23.4 updates/s in float32 (``laneshift bench learner``)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            return None
    flags: set[str] = set()
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() in ("flags", "Features"):
            flags.update(value.split())
    return bool(flags & BF16_FLAGS) if flags else None
