"""The launcher's Ray: a private local cluster (state in a temp dir, no token, loopback only,
reaped with the launcher) or a running cluster (``--cluster``, ``RAY_ADDRESS``), with one clear
line when it cannot be reached.

Room: deploy, the wiring. May import: the contract, ``deploy.processes`` and Ray.
"""

from __future__ import annotations

import contextlib
import inspect
import math
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from typing import Any

from laneshift.config import RunConfig

from .errors import LaunchError
from .processes import end_processes_holding, processes_holding


@contextlib.contextmanager
def _lean_private_cluster() -> Iterator[None]:
    """A private local cluster without three of Ray's side processes it has no use for
    (less memory and a faster start, `laneshift bench run`; docs/performance.md; docs/deploy.md says
    what a local run lacks):

    - the log monitor: it streams worker logs to the driver; ``log_to_driver=False``, the
      components write to ``<run dir>/logs``;
    - the autoscaler monitor: one fixed node has nothing to scale;
    - the API server (``dashboard.py``): with ``include_dashboard=False`` Ray still starts it, with
      one module, ``UsageStatsHead``, and usage stats are off here (``RAY_USAGE_STATS_ENABLED=0``);
      ``ray.init`` also waits for it to come up. Measured: 119 MB of RSS and 0.9 s of ``ray.init``.

    And the dashboard agent runs as it does with a minimal Ray install (``pip install ray``, no
    ``[default]``, ``--minimal``): without the modules that serve the dashboard, job submission
    and Prometheus export of Ray's own metrics, none of which a private cluster serves. Ray decides
    that by importing the optional dependencies (aiohttp, opencensus, opentelemetry, pydantic, ...)
    into the driver, this launcher, for the whole run: 0.26 s of CPU and 22 MB of its RSS.

    Together about 300 MB. ``ray start --head`` has switches for the first two
    (``--include-log-monitor=False``, ``--no-monitor``) but ``ray.init`` has none for any, so its
    parameters are amended as it builds them, its node's ``start_api_server`` does nothing and the
    dependency check answers "minimal", for this one call. Ray is pinned (2.60.0); a Ray without
    these names keeps its defaults."""
    from ray._private import node, parameter
    from ray._private import utils as ray_utils

    init = parameter.RayParams.__init__
    api_server = getattr(node.Node, "start_api_server", None)
    monitors = {"include_log_monitor", "no_monitor"} <= set(inspect.signature(init).parameters)

    def lean(self: Any, *args: Any, **kwargs: Any) -> None:
        init(self, *args, **kwargs)
        self.include_log_monitor, self.no_monitor = False, True

    def no_api_server(self: Any, *, include_dashboard: bool | None, raise_on_failure: bool) -> None:
        # The node's dashboard URL stays None, as with a minimal Ray install.
        if include_dashboard:  # never asked for here; if it were, Ray's own behaviour
            api_server(self, include_dashboard=include_dashboard, raise_on_failure=raise_on_failure)

    dependency_check = getattr(ray_utils, "get_dashboard_dependency_error", None)

    def minimal() -> ImportError:
        return ImportError("a private local cluster runs Ray's dashboard agent as a minimal install does")

    if monitors:
        parameter.RayParams.__init__ = lean
    if api_server is not None:
        node.Node.start_api_server = no_api_server
    if dependency_check is not None:
        ray_utils.get_dashboard_dependency_error = minimal
    try:
        yield
    finally:
        parameter.RayParams.__init__ = init
        if api_server is not None:
            node.Node.start_api_server = api_server
        if dependency_check is not None:
            ray_utils.get_dashboard_dependency_error = dependency_check


class RayConnection:
    """A private local Ray cluster, or a running one joined as a driver. Contacted (and its
    token checked) before any component starts."""

    def __init__(self, address: str | None):
        self.address = address
        self.temp_dir: str | None = None
        self._reaper: subprocess.Popen | None = None

    def open(self, cfg: RunConfig) -> "RayConnection":
        if self.address is not None and (os.environ.get("RAY_AUTH_TOKEN") or os.environ.get("RAY_AUTH_TOKEN_PATH")):
            # A token was given: use it (Ray sends one to an explicit address only in token mode).
            # Set before Ray reads its auth settings.
            os.environ.setdefault("RAY_AUTH_MODE", "token")
        import ray

        if self.address is None:
            os.environ.pop("RAY_ADDRESS", None)  # --local inside a job: a private cluster all the same
            os.environ["RAY_AUTH_MODE"] = "disabled"  # loopback-only cluster; keeps ~/.ray untouched
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            self.temp_dir = tempfile.mkdtemp(prefix="lsray-")  # short: unix socket paths < 108 chars
            self._reaper = _temp_dir_reaper(self.temp_dir)
            d = cfg.deploy
            cpus = (d.router_cpus + cfg.replay.shards * d.replay_cpus + d.learner_cpus
                    + cfg.actor.workers * d.worker_cpus)
            resources: dict[str, float] = {}
            for res, count in ((d.router_resources, 1), (d.replay_resources, cfg.replay.shards),
                               (d.learner_resources, 1)):
                for k, v in res.items():
                    resources[k] = resources.get(k, 0.0) + v * count
            for k, v in d.worker_resources.items():
                resources[k] = resources.get(k, 0.0) + v * cfg.actor.workers
            resources.pop("GPU", None)
            with _lean_private_cluster():
                ray.init(num_cpus=max(math.ceil(cpus), 1), resources=resources or None, include_dashboard=False,
                         _temp_dir=self.temp_dir, _node_ip_address="127.0.0.1", log_to_driver=False,
                         configure_logging=False)
            return self
        if not self.address.startswith("ray://"):
            _probe_gcs(self.address)
        try:
            _join(ray.init, self.address)
        except Exception as exc:  # noqa: BLE001 - Ray raises many kinds; the user needs one line
            raise LaunchError(_ray_connect_error(self.address, exc)) from None
        return self

    def close(self) -> None:
        import ray

        if ray.is_initialized():
            ray.shutdown()
        if self.temp_dir is not None:
            # Ray's shutdown ends its processes through the head; with the head gone before it
            # (Run._cluster_gone), the actors would live on for up to a minute, holding their logs here.
            end_processes_holding(self.temp_dir)
            shutil.rmtree(self.temp_dir, ignore_errors=True)
        if self._reaper is not None:
            self._reaper.terminate()
            try:
                self._reaper.wait(5)
            except subprocess.TimeoutExpired:
                self._reaper.kill()


#: What Ray Client's proxy on the head answers when the server process it starts for this driver
#: (its "specific server") died at once (ray/util/client/server/proxier.py). Seen on a loaded
#: machine: the proxy is a multi-threaded gRPC process, and between fork and exec the child's gRPC
#: event engine failed (its log: ``epoll_wait error: Bad file descriptor``; the kernel's:
#: ``event_engine[...]: segfault ... in cygrpc``); the next process the proxy started ran.
CLIENT_SERVER_FAILED = "Starting Ray client server failed"
#: The same death seen a moment later: the proxy's ``start_specific_server`` found the child alive
#: (``poll()``), then read its command line with psutil after it had died, and answers psutil's
#: error instead (seen in CI: ``psutil.ZombieProcess: PID still exists but it's a zombie``).
CLIENT_SERVER_DIED = ("psutil.ZombieProcess", "psutil.NoSuchProcess")
#: ``ray://`` connections tried when the head's client server fails to start (each try starts a new one;
#: about one start in three failed on a loaded 2-core head, so three tries would still fail about one run in 27).
CLIENT_TRIES = 5


def client_server_failed_to_start(message: str) -> bool:
    """Whether a Ray Client connection failed because the head's server process for this driver
    died as it started (either answer above); a new connection starts a new one."""
    return CLIENT_SERVER_FAILED in message or (
        "start_specific_server" in message and any(s in message for s in CLIENT_SERVER_DIED))


def _join(init: Any, address: str, tries: int = CLIENT_TRIES, out: Any = None) -> None:
    """``init(address=...)`` (``ray.init``); through Ray Client (``ray://``), again up to ``tries``
    times in all while the head says its client server failed to start, a line on ``out`` each time.
    Any other failure is raised at once."""
    for attempt in range(1, tries + 1):
        try:
            init(address=address, log_to_driver=False, configure_logging=False)
            return
        except Exception as exc:  # noqa: BLE001 - Ray raises many kinds
            if not (address.startswith("ray://") and client_server_failed_to_start(str(exc))) or attempt == tries:
                raise
            print(f"Ray Client at {address}: the head's client server for this driver failed to start "
                  f"(try {attempt} of {tries}); connecting again", file=out or sys.stderr, flush=True)
            time.sleep(1.0)


def _probe_gcs(address: str) -> None:
    """Reach the cluster's GCS and check this driver's token in about a second, before anything
    starts (``ray.init`` would print 20 s of InvalidAuthToken warnings, then a long traceback)."""
    from ray._private.services import canonicalize_bootstrap_address
    from ray._raylet import GcsClient

    try:
        gcs = canonicalize_bootstrap_address(address)
    except Exception as exc:  # noqa: BLE001 - e.g. "auto" with no cluster on this node
        raise LaunchError(_ray_connect_error(address, exc)) from None
    if gcs is None:
        raise LaunchError(f"no running Ray cluster found for --cluster {address} (start one with `ray start --head`, "
                          f"or name it as HOST:PORT)")
    try:
        client = GcsClient(address=gcs)
        client.internal_kv_get(b"laneshift-probe", namespace=None, timeout=10)
    except Exception as exc:  # noqa: BLE001
        raise LaunchError(_ray_connect_error(gcs, exc)) from None


def _ray_connect_error(address: str, exc: Exception) -> str:
    text = f"{type(exc).__name__}: {exc}"
    if any(s in text for s in ("InvalidAuthToken", "Unauthenticated", "UNAUTHENTICATED", "AuthenticationError")):
        given = "a wrong token" if os.environ.get("RAY_AUTH_MODE") == "token" else "no token"
        return (f"Ray at {address} requires its authentication token and this driver sent {given}: set "
                f"RAY_AUTH_TOKEN (or RAY_AUTH_TOKEN_PATH) to the cluster's token (`ray get-auth-token` on the "
                f"head prints it; docs/deploy.md), then retry")
    last = text.strip().splitlines()[-1] if text.strip() else type(exc).__name__
    return f"cannot connect to Ray at {address}: {last[:300]}"


def cluster_answers(timeout_s: float = 2.0) -> bool:
    """Whether the connected cluster's GCS still accepts a connection within ``timeout_s``: False
    once the head is gone (a signal to the launcher's whole process group took its private head
    with it, or the head crashed), when no actor can come back and every wait on one would last
    until Ray's own timeout ends this process (60 s, exit 1, no summary). A TCP connect to the GCS
    port, not Ray's ``GcsClient``: that one retries for 40 s before it says the GCS is gone.
    True when this driver cannot tell (Ray Client)."""
    import ray

    try:
        host, port = ray.get_runtime_context().gcs_address.rsplit(":", 1)
    except Exception:  # noqa: BLE001 - a Ray Client driver has no GCS address of its own
        return True
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            return True
    except OSError:
        return False


def _temp_dir_reaper(path: str) -> subprocess.Popen:
    """A tiny watcher that removes the private Ray temp dir if this launcher is killed with -9
    (Ray's own processes die with it: they are started with the parent-death signal)."""
    # It waits as a POSIX shell (about 1 MB of RSS, against 11 MB for a waiting Python), polling
    # its parent in /proc; only once the launcher is gone does it exec Python for the clean-up.
    wait = ('while read -r _ _ _ parent _ < /proc/$$/stat && [ "$parent" = "$1" ]; do sleep 0.5; done\n'
            'shift 2\nexec "$@"\n')
    # Ray's dashboard and runtime-env agents do not die with the launcher: the clean-up ends every
    # process that holds a file open under this run's private temp dir (only Ray's, started by us;
    # their command lines are rewritten to "ray::DashboardAgent", so they are found by their logs).
    code = ("import os,shutil,signal,sys,time\n" + inspect.getsource(processes_holding)
            + inspect.getsource(end_processes_holding)
            + "time.sleep(2)\nend_processes_holding(sys.argv[1])\nshutil.rmtree(sys.argv[1],ignore_errors=True)\n")
    return subprocess.Popen(["/bin/sh", "-c", wait, "laneshift-ray-reaper", str(os.getpid()), path,
                             sys.executable, "-c", code, path], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
