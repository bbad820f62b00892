"""Test helper, not a test file: a real two-host Ray cluster on one machine, in two network namespaces.

``two_hosts(tmp_path)`` makes two "hosts" that see each other only over one link:

    netns lsA-<pid>-<n>  (HOST_A 10.213.7.1/24)  <-- veth pair -->  netns lsB-<pid>-<n>  (HOST_B 10.213.7.2/24)
      ray start --head, resources {"laneshift_head": 100}            ray start --address HOST_A:<port>,
      3 CPUs; the dashboard (jobs API) when asked                    resources {"laneshift_env": 100}, 2 CPUs

Both veth ends are created directly inside the namespaces: nothing is added to the root namespace,
there is no default route in either namespace, and every address used lives on that link. The
namespaces are fresh, so the fixed ports below cannot collide with another Ray on this machine;
each node has a short temp dir of its own (Ray's unix socket paths must stay < 108 chars), so
nothing is written to ``/tmp/ray``.

Ray 2.60 token authentication (read from the installed ray, ``ray/_private/authentication/`` and
``ray/scripts/scripts.py``; docs: https://docs.ray.io/en/latest/ray-security/token-auth.html and
https://docs.ray.io/en/master/ray-core/internals/token-authentication.html):

* ``RAY_AUTH_MODE`` = ``token`` | ``disabled`` (environment only; putting it in ``_system_config``
  is an error). When unset, ``ray.init()`` starting a new local cluster turns token mode on and
  writes a token to ``~/.ray/auth_token`` if there is none (2.59+); ``ray start`` turns it on only
  if a token already exists; ``ray.init(address=<explicit>)`` never turns it on by itself.
* The token, in this order: ``RAY_AUTH_TOKEN`` (the value), ``RAY_AUTH_TOKEN_PATH`` (a file; an
  unreadable or empty one is fatal, no fallback), ``~/.ray/auth_token``. Every node and every
  client must have the same one; ``ray get-auth-token [--generate]`` prints (or creates, under
  ``~/.ray``) it. A token is ``secrets.token_hex(32)``; HTTP clients send ``Authorization: Bearer``.

The harness sets ``RAY_AUTH_MODE=token`` and ``RAY_AUTH_TOKEN_PATH=<tmp>/auth_token`` (a fresh
token, mode 0600) for both ``ray start`` processes and for every command run through
``run_in_a``, so the cluster runs authenticated and ``~/.ray`` is never touched. Raylets spawn the
Ray workers (and a job's driver) with their own environment, so those inherit it.

Every process is started with ``start_new_session=True``; teardown SIGTERMs then SIGKILLs those
process groups, kills by PID anything still inside the two namespaces (``ip netns pids``: only
processes this harness started can be there), deletes the namespaces and the temp dirs, and
fails if any started process survived. Every wait is bounded in time and in count.

Room: tests, a helper the tests import or run. May import: laneshift (any floor), pytest, numpy, the
standard library and what the code under test needs.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

HOST_A = "10.213.7.1"
HOST_B = "10.213.7.2"
PREFIX = 24

BIN = Path(sys.executable).parent  # the venv's bin: tests run with .venv/bin/python
RAY = BIN / "ray"
PYTHON = BIN / "python"

# Fixed ports: inside fresh namespaces nothing else listens, and each node has its own IP.
GCS_PORT = 6390
DASHBOARD_PORT = 8275
NODE_PORTS = {
    "--node-manager-port": 6391,
    "--object-manager-port": 6392,
    "--min-worker-port": 20000,
    "--max-worker-port": 20199,
    "--dashboard-agent-listen-port": 52375,
    "--dashboard-agent-grpc-port": 52376,
    "--runtime-env-agent-port": 52377,
    "--metrics-export-port": 52378,
}
RAY_CLIENT_PORT = 10011
TERM_GRACE_S = 10.0
OBJECT_STORE_BYTES = 256 * 1024 * 1024  # small: the runs move weights and transitions over zenoh

_counter = itertools.count()
_reason_cache: list[str | None] = []


def _ip(*args: str, timeout: float = 15.0, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=timeout, check=check)


def netns_unavailable_reason() -> str | None:
    """None if namespaces and veth pairs can be made here, else why not (for ``pytest.skip``)."""
    if _reason_cache:
        return _reason_cache[0]
    reason = _probe()
    _reason_cache.append(reason)
    return reason


def _probe() -> str | None:
    if sys.platform != "linux":
        return f"network namespaces need Linux, not {sys.platform}"
    if os.geteuid() != 0:
        return "network namespaces need root (euid is %d)" % os.geteuid()
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is missing"
    if not RAY.exists():
        return f"no `ray` next to {sys.executable}"
    a, b = f"lsprobeA-{os.getpid()}", f"lsprobeB-{os.getpid()}"
    try:
        for ns in (a, b):
            r = _ip("netns", "add", ns, check=False)
            if r.returncode:
                return f"`ip netns add` failed: {(r.stderr or r.stdout).strip()}"
        r = _ip("link", "add", f"lspa{os.getpid()}", "netns", a, "type", "veth",
                "peer", "name", f"lspb{os.getpid()}", "netns", b, check=False)
        if r.returncode:
            return f"`ip link add ... type veth` failed: {(r.stderr or r.stdout).strip()}"
        return None
    except (OSError, subprocess.SubprocessError) as exc:
        return f"`ip` failed: {exc}"
    finally:
        for ns in (a, b):
            _ip("netns", "del", ns, check=False)


@dataclass
class TwoHosts:
    """What ``two_hosts`` yields."""

    ns_a: str
    ns_b: str
    veth_a: str
    veth_b: str
    host_a: str
    host_b: str
    ray_address: str  # "10.213.7.1:<gcs port>"
    dashboard_url: str | None  # "http://10.213.7.1:<port>" when started with the dashboard
    env: dict[str, str]  # the environment every command gets (auth token, no usage stats)
    token: str
    token_path: Path
    head_pid: int
    worker_pid: int
    node_ids: dict[str, str] = field(default_factory=dict)  # node ip -> Ray node id
    up_s: float = 0.0  # seconds from the first `ip netns add` to two alive Ray nodes
    logs: Path = Path()
    _children: list[subprocess.Popen] = field(default_factory=list)

    @property
    def node_id_a(self) -> str:
        return self.node_ids[self.host_a]

    @property
    def node_id_b(self) -> str:
        return self.node_ids[self.host_b]

    def run_in_a(self, argv: Sequence[str], env: dict[str, str] | None = None, timeout: float = 120.0,
                 ns: str | None = None) -> subprocess.CompletedProcess:
        """Run ``argv`` in namespace A (or ``ns``) with the cluster's token env plus ``env``.

        Returns the CompletedProcess (stdout and stderr as text). Past ``timeout`` its whole
        process group is killed and the result has ``returncode = -9`` and ``timed_out = True``.
        """
        full_env = {**self.env, **(env or {})}
        cmd = ["ip", "netns", "exec", ns or self.ns_a, *map(str, argv)]
        proc = subprocess.Popen(cmd, env=full_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        self._children.append(proc)
        timed_out = False
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            _killpg(proc.pid, signal.SIGKILL)
            try:
                out, err = proc.communicate(timeout=15)
            except subprocess.TimeoutExpired:  # a grandchild holds the pipes: teardown kills it
                proc.kill()
                out, err = "", "(output lost: the command's pipes stayed open after SIGKILL)"
        result = subprocess.CompletedProcess(cmd, proc.returncode if not timed_out else -9, out, err)
        result.timed_out = timed_out  # type: ignore[attr-defined]
        return result

    def run_in_b(self, argv: Sequence[str], env: dict[str, str] | None = None,
                 timeout: float = 120.0) -> subprocess.CompletedProcess:
        return self.run_in_a(argv, env=env, timeout=timeout, ns=self.ns_b)


def _killpg(pgid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def _netns_pids(ns: str) -> list[int]:
    r = _ip("netns", "pids", ns, check=False)
    return [int(p) for p in r.stdout.split() if p.strip().isdigit()] if r.returncode == 0 else []


def _pids_in_groups(pgids: set[int]) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            if os.getpgid(int(entry)) in pgids:
                found.append(int(entry))
        except (ProcessLookupError, PermissionError):
            pass
    return found


def _tail(path: Path, n: int = 40) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


_WAIT_NODES = r"""
import json, sys, time
import ray
addr, want, budget = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
deadline = time.monotonic() + budget
for attempt in range(60):
    try:
        ray.init(address=addr, log_to_driver=False, logging_level="ERROR", configure_logging=False)
        break
    except Exception as exc:  # GCS not up yet
        if time.monotonic() > deadline:
            raise
        print(f"ray.init attempt {attempt}: {exc!r}", file=sys.stderr, flush=True)
        time.sleep(1.0)
nodes = []
for _ in range(int(budget / 0.5) + 1):
    nodes = [n for n in ray.nodes() if n["Alive"]]
    if len(nodes) >= want or time.monotonic() > deadline:
        break
    time.sleep(0.5)
print(json.dumps([{"id": n["NodeID"], "ip": n["NodeManagerAddress"], "resources": n["Resources"]} for n in nodes]))
ray.shutdown()
"""


@contextlib.contextmanager
def two_hosts(tmp_path: Path, dashboard: bool = False, up_timeout: float = 150.0,
              head_cpus: int = 3, worker_cpus: int = 2) -> Iterator[TwoHosts]:
    """Two namespaces, a veth link, a Ray head in A and a Ray worker node in B; all removed after."""
    reason = netns_unavailable_reason()
    if reason:
        raise RuntimeError(f"two_hosts: {reason}")
    n = next(_counter)
    pid = os.getpid()
    ns_a, ns_b = f"lsA-{pid}-{n}", f"lsB-{pid}-{n}"
    veth_a, veth_b = f"lsa{pid}x{n}", f"lsb{pid}x{n}"  # <= 15 chars
    logs = Path(tmp_path) / f"twohost-{n}"
    logs.mkdir(parents=True, exist_ok=True)
    made_ns: list[str] = []
    temp_dirs: list[str] = []
    procs: list[subprocess.Popen] = []
    hosts: TwoHosts | None = None
    started = time.monotonic()
    body_failed = True
    try:
        _link_namespaces(ns_a, ns_b, veth_a, veth_b, made_ns)

        # ---- the shared secret: a fresh token in a file of our own (never ~/.ray)
        secret_dir = tempfile.mkdtemp(prefix="lstok")
        temp_dirs.append(secret_dir)
        token = secrets.token_hex(32)
        token_path = Path(secret_dir) / "auth_token"
        token_path.write_text(token)
        token_path.chmod(0o600)
        env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token_path),
               "RAY_USAGE_STATS_ENABLED": "0", "PYTHONUNBUFFERED": "1"}
        for var in ("RAY_AUTH_TOKEN", "RAY_ADDRESS"):  # nothing from outside may win over ours
            env.pop(var, None)

        ports = [f"{k}={v}" for k, v in NODE_PORTS.items()]
        tmp_a = tempfile.mkdtemp(prefix="lsA")
        tmp_b = tempfile.mkdtemp(prefix="lsB")
        temp_dirs += [tmp_a, tmp_b]
        head_cmd = ["ip", "netns", "exec", ns_a, str(RAY), "start", "--head", "--block",
                    "--node-ip-address", HOST_A, f"--port={GCS_PORT}", f"--temp-dir={tmp_a}",
                    f"--num-cpus={head_cpus}", "--num-gpus=0", "--resources", json.dumps({"laneshift_head": 100}),
                    f"--object-store-memory={OBJECT_STORE_BYTES}", f"--ray-client-server-port={RAY_CLIENT_PORT}",
                    f"--include-dashboard={'true' if dashboard else 'false'}", "--dashboard-host", HOST_A,
                    f"--dashboard-port={DASHBOARD_PORT}", "--disable-usage-stats", *ports]
        head_log = open(logs / "ray-head.log", "w")
        procs.append(subprocess.Popen(head_cmd, env=env, stdout=head_log, stderr=subprocess.STDOUT,
                                      stdin=subprocess.DEVNULL, start_new_session=True))
        head_log.close()

        def check_alive(what: str) -> None:
            for p, name in zip(procs, ("ray-head", "ray-worker")):
                if p.poll() is not None:
                    raise RuntimeError(f"two_hosts: {name} exited with {p.returncode} while {what}:\n"
                                       + _tail(logs / f"{name}.log"))

        # The head writes <temp dir>/ray_current_cluster once its GCS and raylet are up.
        address_file = Path(tmp_a) / "ray_current_cluster"
        deadline = started + up_timeout
        for _ in range(int(up_timeout / 0.25) + 1):
            if address_file.exists() or time.monotonic() > deadline:
                break
            check_alive("the head started")
            time.sleep(0.25)
        if not address_file.exists():
            raise RuntimeError(f"two_hosts: the Ray head was not up within {up_timeout:.0f} s:\n"
                               + _tail(logs / "ray-head.log"))
        ray_address = f"{HOST_A}:{GCS_PORT}"

        worker_cmd = ["ip", "netns", "exec", ns_b, str(RAY), "start", "--block", "--address", ray_address,
                      "--node-ip-address", HOST_B, f"--temp-dir={tmp_b}", f"--num-cpus={worker_cpus}",
                      "--num-gpus=0", "--resources", json.dumps({"laneshift_env": 100}),
                      f"--object-store-memory={OBJECT_STORE_BYTES}", "--disable-usage-stats", *ports]
        worker_log = open(logs / "ray-worker.log", "w")
        procs.append(subprocess.Popen(worker_cmd, env=env, stdout=worker_log, stderr=subprocess.STDOUT,
                                      stdin=subprocess.DEVNULL, start_new_session=True))
        worker_log.close()

        hosts = TwoHosts(ns_a=ns_a, ns_b=ns_b, veth_a=veth_a, veth_b=veth_b, host_a=HOST_A, host_b=HOST_B,
                         ray_address=ray_address,
                         dashboard_url=f"http://{HOST_A}:{DASHBOARD_PORT}" if dashboard else None,
                         env=env, token=token, token_path=token_path, head_pid=procs[0].pid,
                         worker_pid=procs[1].pid, logs=logs)

        # ---- both nodes alive, as the GCS sees them (an authenticated driver in A asks)
        remaining = max(10.0, deadline - time.monotonic())
        waiter = subprocess.Popen(["ip", "netns", "exec", ns_a, str(PYTHON), "-c", _WAIT_NODES, ray_address, "2",
                                   str(remaining)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, start_new_session=True)
        hosts._children.append(waiter)
        try:
            out, err = waiter.communicate(timeout=remaining + 30)
        except subprocess.TimeoutExpired:
            _killpg(waiter.pid, signal.SIGKILL)
            try:
                out, err = waiter.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                out, err = "", "(the node waiter hung past SIGKILL)"
        check_alive("waiting for two nodes")
        try:
            nodes = json.loads(out.strip().splitlines()[-1])
        except (ValueError, IndexError):
            nodes = []
        hosts.node_ids = {nd["ip"]: nd["id"] for nd in nodes}
        if set(hosts.node_ids) != {HOST_A, HOST_B}:
            raise RuntimeError(f"two_hosts: expected alive Ray nodes on {HOST_A} and {HOST_B}, got {nodes}\n"
                               f"waiter rc {waiter.returncode}: {err[-3000:]}"
                               f"\n-- head --\n{_tail(logs / 'ray-head.log')}"
                               f"\n-- worker --\n{_tail(logs / 'ray-worker.log')}")
        hosts.up_s = time.monotonic() - started
        print(f"\ntwo_hosts: Ray head {ray_address} (ns {ns_a}) + worker {HOST_B} (ns {ns_b}) up in "
              f"{hosts.up_s:.1f} s; token auth on ({token_path})", flush=True)
        yield hosts
        body_failed = False
    finally:
        t0 = time.monotonic()
        survivors = _teardown(procs, (hosts._children if hosts else []), made_ns, temp_dirs, logs)
        print(f"two_hosts: torn down in {time.monotonic() - t0:.1f} s"
              f"{'' if survivors else ', nothing left behind'}", flush=True)
        if survivors:
            msg = f"two_hosts: processes survived teardown: {survivors}"
            print(msg, flush=True)
            if not body_failed:
                raise AssertionError(msg)


def _teardown(procs: list[subprocess.Popen], children: list[subprocess.Popen], namespaces: list[str],
              temp_dirs: list[str], logs: Path) -> list[str]:
    """Stop everything the harness started; returns descriptions of anything that survived."""
    pgids = {p.pid for p in [*procs, *children]}
    for p in [*children, *reversed(procs)]:  # the worker node first, then the head
        if p.poll() is None:
            _killpg(p.pid, signal.SIGTERM)
    # Graceful first, but not for long: a head whose raylet ran tasks takes ~30 s to stop on
    # SIGTERM; the cluster's state is thrown away anyway.
    deadline = time.monotonic() + TERM_GRACE_S
    for p in [*children, *procs]:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
    for pgid in pgids:  # whatever is left in those groups (raylet, GCS, Ray workers, ...)
        _killpg(pgid, signal.SIGKILL)
    # Anything still inside our namespaces was started by us (the namespaces are ours alone).
    for _ in range(40):
        left = [pid for ns in namespaces for pid in _netns_pids(ns)]
        if not left:
            break
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.25)
    for p in [*children, *procs]:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=5)
    survivors = [f"{pid} in {ns}" for ns in namespaces for pid in _netns_pids(ns)]
    survivors += [f"{pid} in process group of a started process" for pid in _pids_in_groups(pgids)
                  if _is_alive(pid)]
    # Keep the Ray session logs next to the test's files, then remove the short temp dirs.
    for d in temp_dirs:
        session_logs = Path(d) / "session_latest" / "logs"
        if session_logs.is_dir():
            with contextlib.suppress(OSError, shutil.Error):
                shutil.copytree(session_logs, logs / f"ray-logs-{Path(d).name}", dirs_exist_ok=True)
        shutil.rmtree(d, ignore_errors=True)
    for ns in namespaces:
        for _ in range(10):
            if _ip("netns", "del", ns, check=False).returncode == 0 or not _ns_exists(ns):
                break
            time.sleep(0.5)
        if _ns_exists(ns):
            survivors.append(f"network namespace {ns}")
    return survivors


def _link_namespaces(ns_a: str, ns_b: str, veth_a: str, veth_b: str, made: list[str]) -> None:
    """Two namespaces (appended to ``made`` as each exists, for the teardown), one veth pair with
    both ends inside them: HOST_A in ``ns_a``, HOST_B in ``ns_b``."""
    for ns in (ns_a, ns_b):
        _ip("netns", "add", ns)
        made.append(ns)
    _ip("link", "add", veth_a, "netns", ns_a, "type", "veth", "peer", "name", veth_b, "netns", ns_b)
    for ns, dev, addr in ((ns_a, veth_a, HOST_A), (ns_b, veth_b, HOST_B)):
        _ip("-n", ns, "addr", "add", f"{addr}/{PREFIX}", "dev", dev)
        _ip("-n", ns, "link", "set", dev, "up")
        _ip("-n", ns, "link", "set", "lo", "up")


@contextlib.contextmanager
def linked_namespaces(tmp_path: Path) -> Iterator[tuple[str, str]]:
    """Two namespaces and their veth link, no Ray (for benchmarks that start their own processes
    with ``ip netns exec``); every process left inside them is killed and both are removed after."""
    reason = netns_unavailable_reason()
    if reason:
        raise RuntimeError(f"linked_namespaces: {reason}")
    n, pid = next(_counter), os.getpid()
    made: list[str] = []
    try:
        _link_namespaces(f"lsA-{pid}-{n}", f"lsB-{pid}-{n}", f"lsa{pid}x{n}", f"lsb{pid}x{n}", made)
        yield made[0], made[1]
    finally:
        survivors = _teardown([], [], made, [], Path(tmp_path))
        if survivors:
            print(f"linked_namespaces: left behind: {survivors}", flush=True)


def _is_alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _ns_exists(ns: str) -> bool:
    return ns in _ip("netns", "list", check=False).stdout.split()


# Run settings of the two-host training tests (test_two_host, test_network_faults): small and
# fast, so learning and weight broadcasts start early, and the placement: router, replay server
# and learner on host A (laneshift_head), env workers on host B (laneshift_env).
FAST = ["actor.send_every=50", "actor.epsilon_decay_steps=1000", "learner.hidden=64,64", "learner.batch_size=64",
        "learner.publish_every=10", "learner.checkpoint_every=100", "replay.min_size=200",
        "replay.samples_per_insert=8", "replay.spi_tolerance=1024", "train.log_every_s=1"]
PLACE = ['deploy.worker_resources={"laneshift_env": 1}', 'deploy.replay_resources={"laneshift_head": 1}',
         'deploy.learner_resources={"laneshift_head": 1}', 'deploy.router_resources={"laneshift_head": 1}',
         "train.eval_episodes=0"]
