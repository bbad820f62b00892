"""The learner process: its entry point (``laneshift learner --config run.yaml``) and the settings
a process that runs a learner gets (the GIL switch interval, the allocator, torch's threads).

Room: learner (component). May import: torch, the contract and laneshift.learner; never another
component.
"""

from __future__ import annotations

import signal
import sys
import threading

import torch

from laneshift import transport
from laneshift.config import RunConfig
from laneshift.envspec import EnvSpec

from .links import ZenohLearnerLinks
from .loop import Learner
from .periodic_eval import EvaluatePolicy


#: The learner process's GIL switch interval (Python's default: 5 ms). The update thread gives the
#: GIL up around each torch op; when the prefetch thread's decode or a zenoh callback holds it, the
#: update waits for up to this long. 0.5 ms: +2.5 % and +4 % env steps/s in two alternating rounds
#: of a 40,000-step run, alternating with the default (`laneshift train --local --workers 2 --scenario
#: straight --env-steps 40000`, rates from its metrics.jsonl; docs/performance.md). A learner process's
#: setting only:
#: in-process mode runs every component in one process and keeps Python's default.
LEARNER_SWITCH_INTERVAL_S = 0.0005


#: glibc malloc in the learner process: blocks up to this size come from the heap, not from a
#: fresh mmap, and freed heap goes back to the system only above TRIM_THRESHOLD_BYTES. With glibc's
#: defaults every update's 256 KB activations and each decoded 175 KB batch were mapped and
#: unmapped anew: 5,000-8,000 page faults a second at ~185 updates/s, 4 % of a core in the kernel
#: (a 40,000-step run, /proc/<pid>/stat); with these, about 5 a second. The learner's working set
#: is a few MB, so the memory kept back is too.
MMAP_THRESHOLD_BYTES = 8 * 2**20
TRIM_THRESHOLD_BYTES = 64 * 2**20


def tune_learner_process() -> None:
    """The learner process's own settings: the GIL switch interval and its allocator."""
    sys.setswitchinterval(LEARNER_SWITCH_INTERVAL_S)
    _tune_malloc()


def _tune_malloc() -> None:
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): keep the allocator's defaults
        return
    m_trim_threshold, m_mmap_threshold = -1, -3  # glibc's <malloc.h>
    mallopt(m_mmap_threshold, MMAP_THRESHOLD_BYTES)
    mallopt(m_trim_threshold, TRIM_THRESHOLD_BYTES)


def run_learner(cfg: RunConfig, spec: EnvSpec, evaluate: EvaluatePolicy | None = None) -> int:
    """Learner process entry point: runs until a stop command, SIGINT or SIGTERM. ``spec``: the
    env's, computed by whoever starts the process; ``evaluate``: for ``train.eval_every``."""
    # learner.torch_threads (default 1), a deliberate choice: the learner shares its node with the
    # replay server, the zenoh router and often actors, and a second intra-op thread would compete
    # with them for the same cores (on a 2-core node, for all of them) while the default MLP's
    # matmuls (batch 256 x 256 units) are small for intra-op parallelism; a GPU learner's CPU side
    # only launches kernels. Measured on a 2-core machine with the whole system running, two threads
    # made the run slower (0.71x and 0.95x env steps/s against one thread; `laneshift bench run
    # --train-args "--workers 2 --set learner.torch_threads=2"` measures a run's env steps/s); raise
    # it on a node whose cores the learner has to itself. Phase 1 (pre-training, actors idle) is the
    # exception: there the learner takes every CPU (learner.phase1_threads, learner/cpus.py).
    torch.set_num_threads(cfg.learner.torch_threads)
    tune_learner_process()
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        # Waits for the router as long as it takes (it may start later; transport.connect_timeout_s
        # bounds it where the config has one), saying so in a line every 30 s.
        session = transport.open_session(cfg.transport, max_message_bytes=cfg.max_message_bytes, who="learner",
                                         stop=stop, batching=False)  # sample requests: see session_config
    except InterruptedError as exc:  # SIGINT/SIGTERM before any router answered
        print(f"learner: {exc}", flush=True)
        return 0
    except ConnectionError as exc:  # the connect timeout passed: one line naming the endpoint
        print(f"learner: {exc}", file=sys.stderr, flush=True)
        return 1
    with session:
        links = ZenohLearnerLinks(session, cfg, spec.schema, stop)
        Learner(cfg, spec, links, stop, evaluate).run()
    return 0
