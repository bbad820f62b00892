"""Two-host system tests: a real Ray cluster over a veth link between two network namespaces
(``tests/twohost.py``), with token authentication on.

* ``test_two_host_ray_cluster_forms``: the harness itself (always runnable where root and ``ip
  netns`` are): a task asking for ``laneshift_env`` runs on host B, the cluster refuses a wrong
  token, host B has no route but the link to host A, nothing is left behind.
* ``test_two_host_train_cluster``: ``laneshift train --cluster 10.213.7.1:<port>`` (and through Ray
  Client, ``ray://10.213.7.1:<client port>``) run in host A;
  env workers must run on host B, the router, replay server and learner on host A.
* ``test_two_host_train_job_submit``: the same run submitted as a Ray job through the dashboard's
  jobs API (``ray job submit``; needs ``ray[default]``), the driver using ``--cluster auto``.

Marked ``twohost``; skipped with the reason where namespaces cannot be made (not root, no ``ip``).
Run: ``.venv/bin/python -m pytest -q -m twohost tests/test_two_host.py -x -s``

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs.
"""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

# tests/ is not a package and pytest runs with --import-mode=importlib: load the helper by path.
_spec = importlib.util.spec_from_file_location("laneshift_tests_twohost", Path(__file__).with_name("twohost.py"))
twohost = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = twohost
_spec.loader.exec_module(twohost)

pytestmark = pytest.mark.twohost

LANESHIFT = twohost.BIN / "laneshift"
# At 2,000 env steps the two workers sometimes spent their whole shares on version 0 within the
# rate limiter's slack, the learner's first weights arriving after their last batch (fresh clones'
# suites on a fast day, in the job-submit and both cluster cases: {'w0': [[0, 20]], 'w1': [[0, 20]]}).
ENV_STEPS = 4000
# Small and fast run settings and the placement on the two hosts: shared with the network-fault tests.
FAST, PLACE = twohost.FAST, twohost.PLACE


@pytest.fixture
def netns_ok() -> None:
    reason = twohost.netns_unavailable_reason()
    if reason:
        print(f"skipping the two-host tests: {reason}")
        pytest.skip(reason)


def _ip_netns_list() -> set[str]:
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, timeout=15).stdout
    return {line.split()[0] for line in out.splitlines() if line.strip()}


def _train_argv(cluster: str, run_dir: Path) -> list[str]:
    argv = [str(LANESHIFT), "train", "--cluster", cluster, "--workers", "2", "--scenario", "lka",
            "--env-steps", str(ENV_STEPS), "--run-dir", str(run_dir)]
    for item in [*PLACE, *FAST]:
        argv += ["--set", item]
    return argv


def _show(result: subprocess.CompletedProcess, what: str, limit: int = 6000) -> str:
    timed = " (TIMED OUT, process group killed)" if getattr(result, "timed_out", False) else ""
    return (f"{what}: rc {result.returncode}{timed}\n-- stdout (tail) --\n{result.stdout[-limit:]}"
            f"\n-- stderr (tail) --\n{result.stderr[-limit:]}")


_PROBE = r"""
import json, sys
import ray
ray.init(address=sys.argv[1], log_to_driver=False, configure_logging=False)

@ray.remote(resources={"laneshift_env": 1}, num_cpus=1)
def on_env_host():
    import ray.util
    return {"ip": ray.util.get_node_ip_address(), "node": ray.get_runtime_context().get_node_id()}

@ray.remote(resources={"laneshift_head": 1}, num_cpus=1)
def on_head_host():
    import ray.util
    return {"ip": ray.util.get_node_ip_address(), "node": ray.get_runtime_context().get_node_id()}

print(json.dumps({"env": ray.get(on_env_host.remote(), timeout=120),
                  "head": ray.get(on_head_host.remote(), timeout=120),
                  "driver_ip": ray.util.get_node_ip_address()}))
"""


def test_two_host_ray_cluster_forms(tmp_path, netns_ok):
    before = _ip_netns_list()
    home_token = Path.home() / ".ray" / "auth_token"
    had_home_token = home_token.exists()
    root_links = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, timeout=15).stdout
    with twohost.two_hosts(tmp_path) as h:
        names = (h.ns_a, h.ns_b)
        assert set(names) <= _ip_netns_list()
        assert h.ray_address == f"{twohost.HOST_A}:{twohost.GCS_PORT}"
        print(f"two hosts up in {h.up_s:.1f} s; nodes {h.node_ids}")

        # A task that needs the env hosts' resource runs on host B; one needing the head's on A.
        r = h.run_in_a([twohost.PYTHON, "-c", _PROBE, h.ray_address], timeout=180)
        assert r.returncode == 0, _show(r, "probe")
        got = json.loads(r.stdout.strip().splitlines()[-1])
        assert got["env"] == {"ip": twohost.HOST_B, "node": h.node_id_b}, got
        assert got["head"] == {"ip": twohost.HOST_A, "node": h.node_id_a}, got
        assert got["driver_ip"] == twohost.HOST_A

        # Authenticated cluster mode: a driver with another token is turned away.
        bad = h.run_in_a([twohost.PYTHON, "-c", f"import ray; ray.init(address='{h.ray_address}')"],
                         env={"RAY_AUTH_TOKEN": "0" * 64}, timeout=90)
        assert bad.returncode != 0 and not getattr(bad, "timed_out", False), _show(bad, "wrong token")
        assert "authenticat" in (bad.stdout + bad.stderr).lower(), _show(bad, "wrong token")
        print("wrong token refused:", [ln for ln in (bad.stdout + bad.stderr).splitlines()
                                        if "authenticat" in ln.lower()][-1][:300])

        # Host B reaches host A over the link and nothing else: no default route, no other route.
        routes = h.run_in_b(["ip", "-4", "route", "show"], timeout=15)
        assert routes.returncode == 0 and "default" not in routes.stdout, routes.stdout
        assert [ln.split()[0] for ln in routes.stdout.splitlines() if ln.strip()] == ["10.213.7.0/24"], routes.stdout
        assert h.run_in_b(["ip", "route", "get", twohost.HOST_A], timeout=15).returncode == 0
        for elsewhere in ("1.1.1.1", "10.213.8.1", "192.168.0.1"):  # route lookups only: nothing is sent
            unreachable = h.run_in_b(["ip", "route", "get", elsewhere], timeout=15)
            assert unreachable.returncode != 0 and "unreachable" in unreachable.stderr.lower(), unreachable
        # Nothing was added to the root namespace: both veth ends live in the namespaces.
        now_links = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, timeout=15).stdout
        for dev in (h.veth_a, h.veth_b):
            assert dev not in root_links and dev not in now_links, dev
        assert h.run_in_a(["ip", "-o", "link", "show", h.veth_a], timeout=15).returncode == 0
    assert not (set(names) & _ip_netns_list())
    assert not {n for n in _ip_netns_list() - before if n.startswith(("lsA-", "lsB-"))}, "a namespace was left behind"
    assert home_token.exists() == had_home_token, "the token went to ~/.ray instead of the harness's temp file"


def _placement_ip(entry: dict, node_ip_by_id: dict[str, str]) -> str | None:
    if "node_ip" in entry:
        return entry["node_ip"]
    return node_ip_by_id.get(entry.get("node_id") or entry.get("node"))


def _check_run(h, run_dir: Path) -> None:
    """The run spread as asked: workers on host B, every transition and weight version crossed the link."""
    summary_path, replay_path = run_dir / "summary.json", run_dir / "replay_stats.json"
    assert summary_path.exists(), f"no {summary_path}; run dir holds {sorted(p.name for p in run_dir.glob('*'))}"
    assert replay_path.exists(), f"no {replay_path}"
    summary = json.loads(summary_path.read_text())
    replay = json.loads(replay_path.read_text())
    ip_by_id = {v: k for k, v in h.node_ids.items()}

    workers = {w["name"]: w for w in summary["workers"]}
    assert len(workers) == 2, workers
    for name, w in workers.items():
        ip = w.get("node_ip") or ip_by_id.get(w.get("node"))
        assert ip == twohost.HOST_B, f"worker {name} ran on {ip} (node {w.get('node')}), not host B"

    # Every transition arrived: no lost batch, and the online table holds all items sent.
    actors = replay["actors"]
    assert set(actors) == set(workers), (set(actors), set(workers))
    for name, a in actors.items():
        assert a["lost_batches"] == 0, (name, a)
        assert a["items"] == workers[name]["env_steps"] > 0, (name, a, workers[name]["env_steps"])
    sent = sum(w["env_steps"] for w in workers.values())
    assert sent == ENV_STEPS
    assert replay["tables"]["online"]["inserted"] == sent == sum(a["items"] for a in actors.values())
    assert replay.get("rejected", {}) == {}, replay.get("rejected")

    # Weight versions reached host B while the workers acted: each worker got weights, and the
    # workers acted with a learned version (> 0). Not each of them: the rate limiter's slack
    # (replay.spi_tolerance) lets a worker make its 1,000 steps on version 0 when the learner is
    # starved of CPU (seen once with the whole suite beside 3 training processes on 2 cores:
    # w1 [[0, 20]], w0 had later versions).
    for name, w in workers.items():
        assert w["weight_updates"] > 0, (name, w)
    assert max(v for w in workers.values() for v, _n in w["version_runs"]) > 0, \
        {name: w["version_runs"] for name, w in workers.items()}

    # The summary names both nodes: router, replay server and learner on A, workers on B.
    assert "placement" in summary, f"summary.json has no 'placement' (keys: {sorted(summary)})"
    placement = summary["placement"]
    where = {comp: _placement_ip(entry, ip_by_id) for comp, entry in placement.items()}
    for role in ("router", "replay", "learner"):
        comps = [c for c in where if role in c.lower()]
        assert comps, f"no {role} in placement {placement}"
        for c in comps:
            assert where[c] == twohost.HOST_A, f"{c} on {where[c]}, not host A: {placement}"
    for name in workers:
        comps = [c for c in where if c == name or c.endswith(f"-{name}") or c.endswith(f"/{name}")]
        assert comps, f"worker {name} not in placement {placement}"
        for c in comps:
            assert where[c] == twohost.HOST_B, f"{c} on {where[c]}, not host B: {placement}"
    assert {twohost.HOST_A, twohost.HOST_B} <= set(where.values()), placement
    print(f"placement {where}; {sent} transitions, 0 lost; weight updates per worker "
          f"{ {n: w['weight_updates'] for n, w in workers.items()} }")


def _client_server_logs(logs: Path, limit: int = 3000) -> str:
    """The head's Ray Client logs (the proxy's and each specific server's), as the harness kept them."""
    found = sorted(logs.glob("ray-logs-lsA*/ray_client_server*"))
    return "\n".join(f"-- {p.name} (tail) --\n{p.read_text(errors='replace')[-limit:]}" for p in found) or \
        f"(no ray_client_server* log under {logs})"


@pytest.mark.parametrize("via", ["gcs", "ray-client"])
def test_two_host_train_cluster(tmp_path, netns_ok, via):
    """``--cluster HOST:PORT`` (a driver on the head) and ``--cluster ray://HOST:10001`` (Ray Client).

    Through Ray Client, the server process the head's proxy starts for the driver can crash between
    fork and exec on a loaded machine (gRPC's event engine in the forked child; the proxy answers
    ``Starting Ray client server failed`` or ``psutil.ZombieProcess``, about one start in three
    here); the driver connects again (``deploy.ray_connection.CLIENT_TRIES``). A run that fails all
    the same fails the test, with the head's client-server logs (kept by the harness at teardown)
    beside the run's output."""
    failed = None
    with twohost.two_hosts(tmp_path) as h:
        run_dir = tmp_path / "run"
        address = h.ray_address if via == "gcs" else f"ray://{twohost.HOST_A}:{twohost.RAY_CLIENT_PORT}"
        started = time.monotonic()
        r = h.run_in_a(_train_argv(address, run_dir), timeout=300)
        retried = r.stderr.count("connecting again")
        print(f"laneshift train --cluster {address}: rc {r.returncode} in {time.monotonic() - started:.0f} s"
              + (f", after {retried} failed start(s) of the head's client server" if retried else ""))
        if r.returncode != 0:
            failed = _show(r, "laneshift train --cluster") + f"\n(logs: {h.logs}, {run_dir / 'logs'})"
        else:
            _check_run(h, run_dir)
    assert failed is None, failed + ("\n" + _client_server_logs(h.logs) if via == "ray-client" else "")


def _has_jobs_cli() -> str | None:
    try:
        import aiohttp  # noqa: F401  (ray[default]: the dashboard and the jobs API)
        import ray.dashboard.modules.job.cli  # noqa: F401
    except ImportError as exc:
        return f"ray[default] is not installed ({exc}); pip install 'ray[default,client]==2.60.0' torch==2.13.0"
    return None


def test_two_host_train_job_submit(tmp_path, netns_ok):
    missing = _has_jobs_cli()
    if missing:
        pytest.skip(missing)
    with twohost.two_hosts(tmp_path, dashboard=True) as h:
        run_dir = tmp_path / "run"
        job_id = f"laneshift-twohost-{int(time.time())}"
        ray_cli = str(twohost.RAY)
        started = time.monotonic()
        r = h.run_in_a([ray_cli, "job", "submit", "--address", h.dashboard_url, "--submission-id", job_id,
                        "--", *_train_argv("auto", run_dir)], timeout=330)
        print(f"ray job submit: rc {r.returncode} in {time.monotonic() - started:.0f} s")
        status = h.run_in_a([ray_cli, "job", "status", "--address", h.dashboard_url, job_id], timeout=60)
        if getattr(r, "timed_out", False):
            h.run_in_a([ray_cli, "job", "stop", "--address", h.dashboard_url, job_id], timeout=60)
        detail = _show(r, "ray job submit") + "\n" + _show(status, "ray job status", 2000)
        plain = re.sub(r"\x1b\[[0-9;]*m", "", status.stdout + status.stderr)  # the CLI colours its output
        assert r.returncode == 0 and f"Job '{job_id}' succeeded" in plain, detail
        _check_run(h, run_dir)


def test_two_host_ray_job_stop_ends_the_run_gracefully(tmp_path, netns_ok):
    """`ray job stop` sends SIGTERM to the driver: checkpoints, a summary that says why, rc 143.
    Ray SIGKILLs a job RAY_JOB_STOP_WAIT_TIME_S (3 by default) after the SIGTERM; the job's
    runtime env gives it 30 s, as docs/deploy.md says to."""
    missing = _has_jobs_cli()
    if missing:
        pytest.skip(missing)
    with twohost.two_hosts(tmp_path, dashboard=True) as h:
        run_dir = tmp_path / "run"
        job_id = f"laneshift-stop-{int(time.time())}"
        ray_cli = str(twohost.RAY)
        argv = [a if a != str(ENV_STEPS) else "10000000" for a in _train_argv("auto", run_dir)]
        r = h.run_in_a([ray_cli, "job", "submit", "--address", h.dashboard_url, "--submission-id", job_id,
                        "--no-wait", "--runtime-env-json", '{"env_vars": {"RAY_JOB_STOP_WAIT_TIME_S": "30"}}',
                        "--", *argv], timeout=120)
        assert r.returncode == 0, _show(r, "ray job submit --no-wait")
        deadline = time.monotonic() + 180
        metrics = run_dir / "metrics.jsonl"
        while time.monotonic() < deadline and not (metrics.exists() and '"env_steps": ' in metrics.read_text()
                                                   and (run_dir / "checkpoints" / "learner_state.pt").exists()):
            time.sleep(1)
        stop = h.run_in_a([ray_cli, "job", "stop", "--address", h.dashboard_url, job_id], timeout=120)
        status = h.run_in_a([ray_cli, "job", "status", "--address", h.dashboard_url, job_id], timeout=60)
        detail = _show(stop, "ray job stop") + "\n" + _show(status, "ray job status", 2000)
        summary = json.loads((run_dir / "summary.json").read_text()) if (run_dir / "summary.json").exists() else {}
        assert summary.get("ended_by") == "SIGTERM", detail + f"\nsummary: {str(summary)[:500]}"
        assert (run_dir / "replay_checkpoint" / "meta.json").exists() and (run_dir / "checkpoints" / "final.safetensors").exists()
        assert 0 < summary["env_steps"] and summary["replay"]["inserted"] + summary["replay"]["lost_items"] == summary["env_steps"]
        print(f"ray job stop: summary ended_by {summary['ended_by']}, {summary['env_steps']} env steps, "
              f"{summary['replay']['inserted']} stored, {summary['replay']['lost_items']} lost")


def test_two_host_sharded_replay_one_shard_per_host(tmp_path, netns_ok):
    """``replay.shards=2`` on two hosts: the shards spread over both nodes (Ray's SPREAD), each
    worker's transitions cross to its own shard, the learner on A samples both, nothing is lost."""
    with twohost.two_hosts(tmp_path, worker_cpus=3) as h:
        run_dir = tmp_path / "run"
        argv = [str(LANESHIFT), "train", "--cluster", h.ray_address, "--workers", "2", "--scenario", "lka",
                "--env-steps", str(ENV_STEPS), "--run-dir", str(run_dir)]
        place = [p for p in PLACE if not p.startswith("deploy.replay_resources")]
        for item in [*place, *FAST, "replay.shards=2"]:
            argv += ["--set", item]
        r = h.run_in_a(argv, timeout=300)
        assert r.returncode == 0, _show(r, "laneshift train --cluster (2 shards)") + f"\n(logs: {h.logs})"
        summary = json.loads((run_dir / "summary.json").read_text())
        ip_by_id = {v: k for k, v in h.node_ids.items()}
        where = {comp: _placement_ip(entry, ip_by_id) for comp, entry in summary["placement"].items()}
        assert {where["replay-server"], where["replay-server-1"]} == {twohost.HOST_A, twohost.HOST_B}, where
        workers = {w["name"]: w for w in summary["workers"]}
        for i in range(2):
            replay = json.loads((run_dir / f"replay_stats_shard{i}.json").read_text())
            actor = replay["actors"][f"w{i}"]
            assert set(replay["actors"]) == {f"w{i}"}
            assert actor["items"] == workers[f"w{i}"]["env_steps"] > 0 and actor["lost_batches"] == 0
            assert replay["rejected"] == {} and replay["sampled_rows"] > 0
        assert summary["replay"]["inserted"] == ENV_STEPS and summary["replay"]["lost_items"] == 0
        print(f"shards on {where['replay-server']} and {where['replay-server-1']}; {ENV_STEPS} transitions, 0 lost")
