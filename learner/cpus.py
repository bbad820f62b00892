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
