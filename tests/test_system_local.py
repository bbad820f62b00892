"""The whole system with 2 local workers: real Ray actors, a zenoh router, replay-server and
learner processes; and once in cluster mode, on a two-node Ray cluster started for the test. Uses
the LKA plant (fast) so each run takes seconds, not minutes.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from laneshift import transport, wire
from laneshift.actors.worker import expand_version_runs
from laneshift.config import load_run_config
from laneshift.tools.chaos.runs import alive as _alive
from laneshift.deploy.processes import descendants as _descendants
from laneshift.deploy.local import train_local
from laneshift.tools.bench.run import process_label
from laneshift.deploy.processes import ProcessGroup, wait_for_file
from laneshift.qnet import load_checkpoint, tensors_digest

# Small and fast, but every mechanism on: rate limiter, prefetch, target syncs, checkpoints.
FAST = {"env.scenario": "lka", "actor.workers": 2, "actor.send_every": 50, "actor.epsilon_decay_steps": 1000,
        "learner.hidden": "64,64", "learner.batch_size": 64, "learner.publish_every": 10,
        "learner.checkpoint_every": 100, "replay.samples_per_insert": 8, "replay.spi_tolerance": 1024,
        "train.eval_episodes": 0, "train.log_every_s": 0.5}


@pytest.fixture(scope="module")
def lka_demos(tmp_path_factory) -> str:
    from laneshift.tools.demos.generate import generate_shard

    out = tmp_path_factory.mktemp("demos") / "lka"
    return str(generate_shard(out, env_id_or_scenario="lka", env_kwargs={}, episodes=6, seed=0))


def run(tmp_path: Path, **overrides) -> tuple[Path, dict, dict]:
    run_dir = tmp_path / "run"
    cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir), **overrides})
    out = io.StringIO()
    rc = train_local(cfg, out=out)
    assert rc == 0, out.getvalue()
    summary = json.loads((run_dir / "summary.json").read_text())
    replay = json.loads((run_dir / "replay_stats.json").read_text())
    return run_dir, summary, replay


def test_retention_async_two_workers(tmp_path, lka_demos):
    """Both workers' transitions arrive; the demo share holds after many wraps; no demo evicted."""
    run_dir, summary, replay = run(tmp_path, **{
        "replay.demo_mode": "retention", "replay.demo_paths": lka_demos, "replay.capacity": 1000,
        "replay.demo_ratio": 0.1, "replay.min_size": 200, "train.env_steps": 6000})
    workers = {w["name"]: w for w in summary["workers"]}
    assert set(workers) == {"w0", "w1"} == set(replay["actors"])
    for name, actor in replay["actors"].items():
        assert actor["items"] == actor["stored"] == workers[name]["env_steps"] > 0
        assert actor["lost_batches"] == 0
    assert sum(a["items"] for a in replay["actors"].values()) == 6000
    assert replay["rejected"] == {}
    # The online part (900) wrapped more than 6 times; 100 demo items stayed, bit for bit.
    assert replay["tables"]["online"]["inserted"] == 6000 and replay["tables"]["online"]["capacity"] == 900
    assert replay["tables"]["demo"]["size"] == 100
    assert replay["demo_share_buffer"] == pytest.approx(0.1)
    assert replay["demo_digest_start"] == replay["demo_digest_end"]
    assert abs(replay["demo_share_recent_samples"] - 0.1) < 0.03, replay["demo_share_recent_samples"]
    # Weight versions reached both actors while they acted.
    for w in workers.values():
        assert w["weight_updates"] >= 3 and max(expand_version_runs(w["version_runs"])) >= 2
    assert (run_dir / "checkpoints" / "final.safetensors").exists()
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))


def test_retention_on_two_replay_shards(tmp_path, lka_demos):
    """replay.shards=2: two replay-server actors, each worker's transitions on its own shard, the
    learner sampling both; the run's summary and the demo share read the two as one."""
    run_dir = tmp_path / "run"
    cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir), "replay.shards": 2,
                                     "replay.demo_mode": "retention", "replay.demo_paths": lka_demos,
                                     "replay.capacity": 1000, "replay.demo_ratio": 0.1, "replay.min_size": 200,
                                     "train.env_steps": 4000})
    out = io.StringIO()
    assert train_local(cfg, out=out) == 0, out.getvalue()
    summary = json.loads((run_dir / "summary.json").read_text())
    shards = [json.loads((run_dir / f"replay_stats_shard{i}.json").read_text()) for i in range(2)]
    assert not (run_dir / "replay_stats.json").exists()
    # w0 -> shard 0, w1 -> shard 1 (wire.shard_of), each stored all of its worker's items.
    workers = {w["name"]: w for w in summary["workers"]}
    for i, replay in enumerate(shards):
        assert set(replay["actors"]) == {f"w{i}"}
        actor = replay["actors"][f"w{i}"]
        assert actor["items"] == actor["stored"] == workers[f"w{i}"]["env_steps"] > 0
        assert actor["lost_batches"] == 0 and replay["rejected"] == {}
        assert replay["tables"]["online"]["capacity"] == 450 and replay["tables"]["demo"]["size"] == 50
        assert replay["demo_share_buffer"] == pytest.approx(0.1)
        assert replay["sampled_rows"] > 0  # the learner sampled both shards
        assert (run_dir / f"replay_checkpoint_shard{i}" / "meta.json").exists()
    assert summary["replay"]["inserted"] == 4000 and summary["replay"]["lost_batches"] == 0
    sampled = sum(r["sampled_rows"] for r in shards)
    demo = sum(r["sampled_demo_rows"] for r in shards)
    assert abs(demo / sampled - 0.1) < 0.03, demo / sampled
    assert "replay-server on" in out.getvalue() and "replay-server-1 on" in out.getvalue()
    for w in workers.values():
        assert w["weight_updates"] >= 2


def test_rehearsal_phase1_stores_nothing_and_phase2_starts_from_it(tmp_path, lka_demos):
    run_dir, summary, replay = run(tmp_path, **{
        "replay.demo_mode": "rehearsal", "replay.demo_paths": lka_demos, "learner.phase1_updates": 150,
        "replay.min_size": 200, "train.env_steps": 2000})
    assert replay["phase"] == 2
    # Every stored item was made in phase 2 (actors only act once the phase-1 network exists).
    assert replay["tables"]["online"]["inserted"] == 2000
    assert all(v >= 1 for w in summary["workers"] for v in expand_version_runs(w["version_runs"]))
    phase1, meta = load_checkpoint(run_dir / "checkpoints" / "phase1.safetensors")
    assert meta["phase"] == "1" and int(meta["updates"]) == 150
    # Version 1 is the first phase-2 broadcast. No later version can exist before some worker acted
    # with it (the learner needs min_size inserts first), so at least one worker started on it; a
    # worker whose Ray process came up later joins at the newest version instead.
    first_on_v1 = [w for w in summary["workers"] if expand_version_runs(w["version_runs"])[0] == 1]
    assert first_on_v1
    for w in first_on_v1:
        assert w["first_weights_sha256"] == tensors_digest(phase1)
    # Phase 1 ran on every CPU while the actors waited (learner.phase1_threads, learner/cpus.py).
    if hasattr(os, "sched_getaffinity") and len(os.sched_getaffinity(0)) >= 2:
        assert "learner: phase 1 on CPUs" in (run_dir / "logs" / "learner.log").read_text()


def test_sync_mode_never_acts_on_stale_weights(tmp_path):
    _, summary, replay = run(tmp_path, **{"train.parallel": "sync", "train.env_steps": 1000,
                                          "replay.min_size": 200, "learner.updates_per_round": 4})
    used = [expand_version_runs(w["version_runs"]) for w in summary["workers"]]
    # Round k of every worker is acted with version k: the newest, never an older one.
    assert used[0] == used[1] == list(range(len(used[0])))
    assert len(used[0]) == 10
    assert replay["rejected"] == {}


@pytest.fixture
def replay_server_process(tmp_path):
    """A router and a replay-server process, as `laneshift train` starts them."""
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    cfg = load_run_config(overrides={**FAST, "transport.router": endpoint, "train.run_dir": str(tmp_path),
                                     "replay.min_size": 2})
    from laneshift.config import save_run_config

    path = save_run_config(cfg, tmp_path / "config.yaml")
    group = ProcessGroup(tmp_path / "logs")
    py = [sys.executable, "-m", "laneshift"]
    try:
        group.start("router", [*py, "router", "--listen", endpoint])
        group.start("replay-server", [*py, "replay-server", "--config", str(path), "--ready-file",
                                      str(tmp_path / "ready")])
        wait_for_file(tmp_path / "ready", 60, group, "replay-server")
        yield cfg, group
    finally:
        group.stop_all()


def _batch(n: int, obs: np.ndarray | None = None, seq: int = 0) -> wire.TransitionBatch:
    obs = np.zeros((n, 6), np.float32) if obs is None else obs
    return wire.TransitionBatch.from_arrays(actor="w9", seq=seq, weights_version=0, phase=0, env_steps=n, obs=obs,
                                            action=np.zeros(n), reward=np.zeros(n, np.float32), next_obs=obs,
                                            terminated=np.zeros(n), truncated=np.zeros(n))


def test_malformed_messages_are_counted_and_dropped(replay_server_process):
    cfg, group = replay_server_process
    run_id = cfg.transport.run_id
    good = wire.encode_transitions(_batch(5))
    with transport.open_session(cfg.transport) as session:
        pub = transport.data_publisher(session, wire.transitions_key(run_id, "w9"))
        assert transport.wait_matching(pub, 30)  # else the puts below go nowhere
        pub.put(b"not a laneshift message at all")
        pub.put(good[:-7])  # truncated
        pub.put(wire.encode_transitions(_batch(3, np.zeros((3, 5), np.float32))))  # wrong shape
        nan = np.zeros((2, 6), np.float32)
        nan[1, 2] = np.nan
        pub.put(wire.encode_transitions(_batch(2, nan, seq=1)))  # NaN
        pub.put(good)
        stats = {}
        for _ in range(50):
            reply = transport.query(session, wire.replay_stats_key(run_id), b"", 2.0)
            stats = wire.decode_json(reply) if reply else {}
            if stats.get("tables", {}).get("online", {}).get("size") == 5:
                break
            time.sleep(0.1)
    assert stats["rejected"] == {"bad_magic": 1, "truncated": 1, "bad_shape": 1, "non_finite": 1}
    assert stats["tables"]["online"]["size"] == 5
    group.check_alive()  # the server kept running


def test_a_router_process_never_imports_numpy():
    """A router actor's process builds its router as ``RouterActor`` does (its config without an
    env spec, the builder, a listening session) and never loads the wire module or numpy (13 MB of a
    run's peak memory, which `laneshift bench run` measures per process)."""
    port = transport.free_tcp_port()
    code = ("import sys; from laneshift.deploy.actors import _config; from laneshift.deploy.builder import Builder; "
            "from laneshift.config import RunConfig; cfg, spec = _config(RunConfig().to_dict()); "
            f"r = Builder(cfg, spec).router('tcp/127.0.0.1:{port}').start(announce=False); r.close(); "
            "print(sorted(m for m in ('numpy', 'laneshift.wire', 'laneshift.envspec') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"


def _train_until_it_learns(tmp_path: Path, **popen: object) -> tuple[subprocess.Popen, list[str]]:
    """``laneshift train --local`` (2 workers, the LKA plant) started and read until its actors,
    learner and replay server are all working."""
    cmd = [sys.executable, "-m", "laneshift", "train", "--local", "--workers", "2", "--scenario", "lka",
           "--env-steps", "10000000", "--run-dir", str(tmp_path / "run"), "--set", "train.log_every_s=0.5",
           "--set", "learner.hidden=32"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, **popen)
    lines = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        lines.append(line)
        if " upd " in line and "steps       0/" not in line:
            return proc, lines  # actors, learner and replay server are all working
    proc.kill()
    pytest.fail("training never started:\n" + "".join(lines))


def _assert_none_left(family: set[int]) -> None:
    """Every process of a run's family ends within 30 s of its launcher."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(_alive(p) for p in family):
        time.sleep(0.2)
    assert not [p for p in family if _alive(p)], "processes left behind"


def test_sigint_leaves_no_process_behind(tmp_path):
    # SIGINT at its default in the child: a test run started in the background from a
    # non-interactive shell inherits SIGINT ignored (POSIX), and Python then never raises
    # KeyboardInterrupt, which is right for a background job but not what this test is about.
    proc, lines = _train_until_it_learns(tmp_path, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        family = _descendants(proc.pid)
        assert len(family) >= 5, family  # replay server, learner, Ray's processes and workers
        # What keeps a run's peak memory down (`laneshift bench run`): no log monitor, autoscaler
        # monitor nor API server (dashboard.py) in a private cluster, and the launcher holds no
        # simulator while training (the env's spec came from a child process).
        labels = {process_label(p, proc.pid) for p in family}
        assert "ray gcs" in labels and not labels & {"ray log monitor", "ray monitor", "ray dashboard"}, labels
        # The router runs in the launcher (deploy.router_in auto, local mode), and the temp-dir
        # watcher waits as a shell (Python starts only for its clean-up).
        assert "router" not in labels and "temp-dir watcher" in labels, labels
        # Nor Ray's dashboard dependencies: the agent runs as a minimal install's (no check imports them).
        maps = Path(f"/proc/{proc.pid}/maps").read_text()
        assert "pygame" not in maps and "aiohttp" not in maps
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=90)
        assert proc.returncode == 130, "".join(lines) + rest
        assert "SIGINT received; stopping gracefully" in rest
        _assert_none_left(family)
    finally:
        if proc.poll() is None:
            proc.kill()


def test_sigterm_to_the_whole_process_group_ends_the_run(tmp_path):
    """``timeout``, a CI runner or a closed terminal signals the run's whole process group: its
    private Ray head (gcs, raylet) and every actor get the SIGTERM too and are gone while the
    launcher stops the run. The stop then finds each component dead with no Ray to bring it back:
    it says so in one line each and ends, not waiting for a restart that cannot come."""
    proc, lines = _train_until_it_learns(tmp_path, start_new_session=True)
    try:
        family = _descendants(proc.pid)
        started = time.monotonic()
        os.killpg(proc.pid, signal.SIGTERM)
        rest, _ = proc.communicate(timeout=150)
        took = time.monotonic() - started
        assert proc.returncode == 143, "".join(lines) + rest
        assert "SIGTERM received; stopping gracefully" in rest, rest
        assert took < 50, f"the stop took {took:.0f} s:\n{rest}"  # before Ray's 60 s without its GCS end it
        assert "train: Ray's head does not answer: every component ended with it" in rest, rest
        summary = json.loads((tmp_path / "run" / "summary.json").read_text())
        assert summary["ended_by"] == "SIGTERM" and summary["env_steps"] > 0, summary
        _assert_none_left(family)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_a_head_that_dies_mid_run_ends_the_run_in_one_line(tmp_path):
    """The head's GCS and raylet killed (its node crashed): the actors go on talking to each other
    and the learner, so only asking the head finds it gone. The run ends in one line within
    ``HEAD_LOST_S`` and a probe, before Ray's driver would end itself 60 s after losing its GCS
    (exit 1 with none of laneshift's words), and leaves no process behind."""
    from laneshift.deploy.supervision import HEAD_LOST_S, HEAD_PROBE_S

    proc, lines = _train_until_it_learns(tmp_path, start_new_session=True)
    try:
        family = _descendants(proc.pid)
        head = [p for p in family if process_label(p, proc.pid) in ("ray gcs", "ray raylet")]
        assert len(head) == 2, [process_label(p, proc.pid) for p in family]
        started = time.monotonic()
        for pid in head:
            os.kill(pid, signal.SIGKILL)
        rest, _ = proc.communicate(timeout=120)
        took = time.monotonic() - started
        assert proc.returncode == 1, "".join(lines) + rest
        assert f"train: Ray's head has not answered for {HEAD_LOST_S:.0f} s: every component ended" in rest, rest
        # The close's slack: 46 s in all here with a training run beside the test on the 2 CPUs.
        assert took < HEAD_LOST_S + 2 * HEAD_PROBE_S + 25 < 60, f"it took {took:.0f} s:\n{rest}"
        assert "Failed to connect to GCS" not in rest, rest
        _assert_none_left(family)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_cluster_mode_spreads_workers_over_two_ray_nodes(tmp_path, monkeypatch):
    """``laneshift train --cluster ADDRESS`` against a real two-node Ray cluster (two raylets
    with one CPU each, as ``ray.cluster_utils`` runs them on one machine): one worker lands on each
    node, both connect to the router at the head's address, and every transition arrives."""
    import tempfile

    import ray._private.utils
    from ray.cluster_utils import Cluster

    from laneshift.deploy.cluster import train_cluster

    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # before the nodes start: they inherit it
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")
    # The cluster helper records its address in /tmp/ray/ray_current_cluster; keep /tmp/ray untouched.
    monkeypatch.setattr(ray._private.utils, "write_ray_address", lambda *a, **k: None)
    ray_tmp = tempfile.mkdtemp(prefix="lsc-")  # short: Ray's unix socket paths must stay < 108 chars
    # The head offers what the services ask for; each node has room for one env worker.
    cluster = Cluster(initialize_head=True,
                      head_node_args={"num_cpus": 1, "temp_dir": ray_tmp, "include_dashboard": False,
                                      "resources": {"laneshift_replay": 1, "laneshift_learner": 1}})
    try:
        cluster.add_node(num_cpus=1, temp_dir=ray_tmp)
        cluster.wait_for_nodes()
        run_dir = tmp_path / "run"
        placement = {"deploy.replay_cpus": 0, "deploy.learner_cpus": 0,
                     "deploy.router_resources": '{"laneshift_replay": 0.01}',
                     "deploy.replay_resources": '{"laneshift_replay": 0.5}',
                     "deploy.learner_resources": '{"laneshift_learner": 1}'}
        # Three workers of one CPU on two one-CPU nodes: refused before any actor exists, with the numbers.
        too_big = load_run_config(overrides={**FAST, **placement, "actor.workers": 3,
                                             "train.run_dir": str(tmp_path / "too-big")})
        out, began = io.StringIO(), time.monotonic()
        assert train_cluster(too_big, cluster.address, out=out) == 1
        assert ("cannot place this run on the cluster: the run needs 3 CPU (router 0, replay-server 0, learner 0, "
                "workers 3) and the cluster has 2 on 2 nodes") in out.getvalue(), out.getvalue()
        assert time.monotonic() - began < 60
        cfg = load_run_config(overrides={
            **FAST, **placement, "train.run_dir": str(run_dir), "train.env_steps": 4000, "replay.min_size": 200})
        out = io.StringIO()
        assert train_cluster(cfg, cluster.address, out=out) == 0, out.getvalue()
    finally:
        cluster.shutdown()
        shutil.rmtree(ray_tmp, ignore_errors=True)
    summary = json.loads((run_dir / "summary.json").read_text())
    replay = json.loads((run_dir / "replay_stats.json").read_text())
    nodes = {w["name"]: w["node"] for w in summary["workers"]}
    assert set(nodes) == {"w0", "w1"} and len(set(nodes.values())) == 2, nodes
    head = summary["placement"]["replay-server"]["node_id"]
    assert summary["placement"]["learner"]["node_id"] == summary["placement"]["router"]["node_id"] == head
    assert summary["replay"]["lost_items"] == 0
    for w in summary["workers"]:
        assert replay["actors"][w["name"]]["items"] == w["env_steps"] > 0
    assert sum(w["env_steps"] for w in summary["workers"]) == 4000
    assert (run_dir / "checkpoints" / "final.safetensors").exists()
