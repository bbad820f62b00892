"""``deploy.learner_core``: the learner on a CPU of its own, everything else of the run off it.

The launcher makes the default (-2, auto) concrete (``resolve_learner_core``). Then two halves.
Each component process pins itself when it starts (``pin_process``: the learner to its CPU, any
other component to the node's other CPUs). In local mode the launcher also moves
itself and every Ray process it started off the learner's CPU once the components run
(``pin_process_tree``): the GCS, the raylet, the dashboard and its agents. Ray
workers started later (a restarted component) are the raylet's children and inherit its mask, so
the learner's CPU runs the learner alone; a restarted learner pins itself back onto it.

Room: deploy, the wiring. May import: the standard library, ``deploy.processes`` and the contract (``laneshift.cpus``
moves the threads).
"""

from __future__ import annotations

import os

from laneshift.cpus import set_thread_masks

from .processes import descendants


def resolve_learner_core(learner_core: int, local: bool) -> int:
    """``deploy.learner_core`` -2 (auto) made concrete by the launcher: in local mode the last CPU
    the launcher may use, when it may use two or more (one CPU: nothing to set apart); a cluster
    run's nodes are not the launcher's machine, so auto pins nothing there. -1 and k stay."""
    if learner_core != -2:
        return learner_core
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    return cpus[-1] if local and len(cpus) >= 2 else -1


def pin_process(learner_core: int, learner: bool) -> str | None:
    """This process's threads on CPU ``learner_core`` (the learner) or on the node's other CPUs
    (any other component). Threads started later inherit it. Returns what was done, for the
    component's log, or None when off or not possible here."""
    if learner_core < 0 or not hasattr(os, "sched_setaffinity"):
        return None
    # In local mode this process may have inherited a mask without the learner's CPU already
    # (pin_process_tree on the raylet): the node's CPUs are that mask and the learner's.
    cpus = os.sched_getaffinity(0) | {learner_core}
    mine = {learner_core} if learner else cpus - {learner_core}
    if len(cpus) < 2 or not set_thread_masks(mine) or os.sched_getaffinity(0) != mine:
        return f"deploy.learner_core {learner_core}: not pinned (this process may use CPUs {sorted(os.sched_getaffinity(0))})"
    return f"pinned to CPUs {sorted(mine)} (deploy.learner_core {learner_core})"


def own_cpus() -> set[int] | None:
    """The CPUs this process may use now (None where affinity is not supported), for
    ``restore_own_cpus`` after ``pin_process_tree`` moved it."""
    return os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None


def restore_own_cpus(cpus: set[int] | None) -> None:
    """Every thread of this process back on ``cpus``: a launcher called as a library (the tests, a
    notebook) must not stay off the learner's CPU after its run."""
    if cpus:
        set_thread_masks(cpus)


def pin_process_tree(learner_core: int, skip: frozenset[int] | set[int] = frozenset()) -> int:
    """Local mode, once the components run: this launcher and all its descendants (Ray's own
    processes, the components' worker processes) but ``skip`` (the learner's) off CPU
    ``learner_core``. Returns how many processes were moved."""
    if learner_core < 0 or not hasattr(os, "sched_setaffinity"):
        return 0
    others = os.sched_getaffinity(0) - {learner_core}
    if not others:
        return 0
    root = os.getpid()
    return sum(set_thread_masks(others, pid) for pid in ({root} | descendants(root)) - set(skip))
