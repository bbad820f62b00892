"""The control plane stays bounded and the run's state knows its owner: stats replies the same
size for 2 or 4,096 actors, per-actor stats paged, a restarted actor's resume point, sequence
gaps counted in items, checkpoints refused across runs, the rate limiter not frozen after a
restore, checkpoint writes that fail on a full disk, and the learner surviving a bad reply.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import dataclasses
import errno
import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ConfigError, ReplayConfig, load_run_config
from laneshift.deploy.builder import Builder
from laneshift.replay_server.checkpoint import CheckpointError, restore_checkpoint, write_checkpoint
from laneshift.replay_server.actor_ledger import MAX_ACTOR_PAGE
from laneshift.replay_server.core import ACTORS_IN_STATS, ReplayCore

SCHEMA = wire.TransitionSchema((4,), "float32", 9)


def msg(actor: str, seq: int, n: int = 1, env_steps: int | None = None) -> bytes:
    obs = np.zeros((n, 4), np.float32)
    return wire.encode_transitions(wire.TransitionBatch.from_arrays(
        actor=actor, seq=seq, weights_version=0, phase=0, env_steps=(seq + 1) * n if env_steps is None else env_steps,
        obs=obs, action=np.zeros(n), reward=np.zeros(n, np.float32), next_obs=obs, terminated=np.zeros(n),
        truncated=np.zeros(n)))


def test_stats_reply_size_does_not_grow_with_the_number_of_actors():
    sizes = {}
    for n in (2, 4096):
        core = ReplayCore(ReplayConfig(capacity=10_000, min_size=1), SCHEMA)
        for i in range(n):
            assert core.ingest(msg(f"a{i:05d}", 0)) is None
        body = wire.encode_json(core.stats())  # what the replay/stats queryable sends
        sizes[n] = len(body)
        stats = wire.decode_json(body)
        assert stats["actors_total"]["count"] == n and stats["actors_total"]["items"] == n
        assert len(stats["actors"]) == min(n, ACTORS_IN_STATS)
    assert sizes[4096] < 2 * sizes[2] + 4096, sizes  # flat, and far below the 64 KiB JSON limit
    page = core.handle_control({"cmd": "actors", "offset": 4000, "limit": 10_000})
    assert page["ok"] and page["total"] == 4096 and len(page["actors"]) == 96
    assert list(page["actors"])[0] == "a04000"
    assert len(core.actor_page(0, 10**6)["actors"]) == MAX_ACTOR_PAGE
    assert len(wire.encode_json(core.actor_page(0, MAX_ACTOR_PAGE))) < wire.MAX_HEADER_BYTES


def test_resume_point_and_lost_items_of_a_gap():
    core = ReplayCore(ReplayConfig(capacity=1000, min_size=1), SCHEMA)
    assert core.actor_state("w0") == {"env_steps": 0, "next_seq": 0, "known": 0}
    for seq in range(3):
        core.ingest(msg("w0", seq, n=10))
    assert core.actor_state("w0") == {"env_steps": 30, "next_seq": 3, "known": 1}
    core.ingest(msg("w0", 6, n=10))  # seq 3, 4, 5 never arrived: 3 batches, 30 items
    assert core.actors["w0"]["lost_batches"] == 3 and core.actors["w0"]["lost_items"] == 30
    # A server with no record (restarted without a checkpoint) counts an actor's first batches too.
    fresh = ReplayCore(ReplayConfig(capacity=1000, min_size=1), SCHEMA)
    fresh.ingest(msg("w0", 7, n=10))
    assert fresh.actors["w0"]["lost_batches"] == 7 and fresh.actors["w0"]["lost_items"] == 70


def test_checkpoint_of_another_run_is_refused_and_restore_does_not_freeze_inserts(tmp_path):
    cfg = ReplayConfig(capacity=1000, min_size=10, samples_per_insert=8, spi_tolerance=64)
    core = ReplayCore(cfg, SCHEMA)
    core.identity = {"run_id": "a", "config_digest": "x"}
    for seq in range(40):
        core.ingest(msg("w0", seq, n=10))
    assert not core.insert_allowed()  # 390 items owe the learner 3,120 rows: actors wait
    write_checkpoint(core, tmp_path / "ckpt")
    other = ReplayCore(cfg, SCHEMA)
    other.identity = {"run_id": "b", "config_digest": "x"}
    with pytest.raises(CheckpointError, match="run_id 'a'"):
        restore_checkpoint(other, tmp_path / "ckpt")
    same = ReplayCore(cfg, SCHEMA)
    same.identity = {"run_id": "a", "config_digest": "x"}
    assert restore_checkpoint(same, tmp_path / "ckpt") == 400
    assert same.insert_allowed()  # restored items count as sampled already: actors go on at once


@pytest.fixture
def tiny_disk(tmp_path):
    """A 1 MiB tmpfs: a real full disk (needs root and mount; skipped otherwise)."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_disk_fails_the_checkpoint_with_oserror_and_keeps_the_old_one(tiny_disk):
    """numpy memmap copies died with SIGBUS on a full disk; ordinary writes raise OSError."""
    schema = wire.TransitionSchema((64,), "float32", 9)
    small = ReplayCore(ReplayConfig(capacity=200, min_size=1), schema)
    obs = np.ones((100, 64), np.float32)
    small.ingest(wire.encode_transitions(wire.TransitionBatch.from_arrays(
        actor="w0", seq=0, weights_version=0, phase=0, env_steps=100, obs=obs, action=np.zeros(100),
        reward=np.zeros(100, np.float32), next_obs=obs, terminated=np.zeros(100), truncated=np.zeros(100))))
    assert write_checkpoint(small, tiny_disk / "ckpt")["items"] == 100  # ~110 KB: fits
    big = ReplayCore(ReplayConfig(capacity=5000, min_size=1), schema)  # ~2.7 MB: does not
    with pytest.raises(OSError) as err:
        write_checkpoint(big, tiny_disk / "ckpt")
    assert err.value.errno == errno.ENOSPC
    fresh = ReplayCore(ReplayConfig(capacity=200, min_size=1), schema)
    assert restore_checkpoint(fresh, tiny_disk / "ckpt") == 100  # the previous checkpoint is intact


def test_learner_links_read_an_error_reply_as_no_answer():
    from laneshift.learner.links import _json_or_none

    assert _json_or_none(None) is None
    assert _json_or_none(wire.encode_error("too_large", "x")) is None
    assert _json_or_none(b"garbage") is None
    assert _json_or_none(wire.encode_json({"ok": True})) == {"ok": True}


def test_deploy_config_and_placements():
    cfg = load_run_config(overrides={"actor.workers": 3, "transport.run_id": "r1",
                                     "deploy.learner_resources": '{"GPU": 1, "laneshift_learner": 1}',
                                     "deploy.replay_resources": "laneshift_replay=1,big_mem=0.5",
                                     "deploy.max_restarts": 2})
    b = Builder(cfg)
    learner = b.placement("learner").ray_options()
    assert learner["num_gpus"] == 1.0 and learner["resources"] == {"laneshift_learner": 1.0}
    assert learner["name"] == "r1-learner" and learner["max_restarts"] == 2 and learner["max_concurrency"] > 1
    assert b.placement("replay-server").ray_options()["resources"] == {"laneshift_replay": 1.0, "big_mem": 0.5}
    assert "scheduling_strategy" not in b.placement("replay-server").ray_options()
    sharded = Builder(cfg.replace(replay=dataclasses.replace(cfg.replay, shards=2, min_size=2)))
    assert sharded.replay_servers == ["replay-server", "replay-server-1"]
    assert [sharded.placement(n).ray_options()["scheduling_strategy"] for n in sharded.replay_servers] == ["SPREAD"] * 2
    assert sharded.placement("replay-server-1").ray_options()["name"].endswith("-replay-server-1")
    assert b.placement("w2").ray_options()["num_cpus"] == 1.0 and "resources" not in b.placement("w2").ray_options()
    assert b.budgets == [7, 7, 6] or sum(b.budgets) == cfg.train.env_steps
    with pytest.raises(ValueError):
        b.placement("w3")
    assert b.router_port(local=False) == 7447
    with pytest.raises(ConfigError, match="deploy.worker_resources"):
        load_run_config(overrides={"deploy.worker_resources": '{"CPU": 2}'})
    with pytest.raises(ConfigError, match="deploy.replay_resources"):
        load_run_config(overrides={"deploy.replay_resources": "nonsense"})
    with pytest.raises(ConfigError, match="learner.device"):
        load_run_config(overrides={"learner.device": "tpu"})


class _NoLinks:
    """LearnerLinks that record what the learner publishes (no replay server needed)."""

    def __init__(self):
        self.versions: list[int] = []

    def publish_weights(self, weights: wire.Weights) -> None:
        self.versions.append(weights.version)

    def publish_stats(self, status, final: bool = False) -> None: ...
    def replay_stats(self): return None
    def set_phase(self, phase): return True
    def take_episodes(self): return []
    def stop_requested(self): return False


def test_a_restarted_learner_resumes_its_state_above_every_published_version(tmp_path):
    from laneshift.actors.envs import spec_of
    from laneshift.learner.loop import Learner

    cfg = load_run_config(overrides={"env.scenario": "lka", "train.run_dir": str(tmp_path), "learner.hidden": "16"})
    spec = spec_of(cfg.env)
    first = Learner(cfg, spec, _NoLinks(), threading.Event())
    batch = {"obs": np.zeros((8, *spec.schema.obs_shape), np.float32), "action": np.zeros(8, np.int64),
             "reward": np.ones(8, np.float32), "next_obs": np.zeros((8, *spec.schema.obs_shape), np.float32),
             "terminated": np.zeros(8, np.uint8), "steps": np.ones(8, np.uint8)}
    for _ in range(5):
        first.agent.update(batch)
    first.version = 3
    assert first.save_state()
    first.version = 9  # published after the state was saved: a restart must not reuse 4..9
    first.publish()
    second = Learner(cfg, spec, _NoLinks(), threading.Event())
    assert second.restored_from == {"updates": 5, "version": 10, "phase": 0, "path": str(second.state_path),
                                    "updates_lost": 0}
    for a, b in zip(first.agent.optimizer.state_dict()["state"].values(),
                    second.agent.optimizer.state_dict()["state"].values()):
        assert torch_equal(a["exp_avg"], b["exp_avg"])


def test_a_learner_restarted_before_its_first_state_save_publishes_above_every_version_and_counts_its_loss(tmp_path):
    from laneshift.actors.envs import spec_of
    from laneshift.deploy.summary import _updates_lost_text
    from laneshift.learner.loop import Learner

    cfg = load_run_config(overrides={"env.scenario": "lka", "train.run_dir": str(tmp_path), "learner.hidden": "16"})
    spec = spec_of(cfg.env)
    assert Learner(cfg, spec, _NoLinks(), threading.Event()).restored_from is None  # a new run
    links = _NoLinks()
    first = Learner(cfg, spec, links, threading.Event())
    batch = {"obs": np.zeros((8, *spec.schema.obs_shape), np.float32), "action": np.zeros(8, np.int64),
             "reward": np.ones(8, np.float32), "next_obs": np.zeros((8, *spec.schema.obs_shape), np.float32),
             "terminated": np.zeros(8, np.uint8), "steps": np.ones(8, np.uint8)}
    for version in range(1, 8):  # 7 versions published, 3 updates each, and never a state save
        for _ in range(3):
            first.agent.update(batch)
        first.version = version
        first.publish()
    assert not first.state_path.exists()
    second_links = _NoLinks()
    second = Learner(cfg, spec, second_links, threading.Event())
    assert second.restored_from == {"updates": 0, "version": 8, "phase": 0, "path": None, "updates_lost": 21}
    second.publish()
    assert second_links.versions == [8] and max(links.versions) == 7  # strictly above what actors saw
    assert _updates_lost_text(second.restored_from) == " (restarted without a state checkpoint: 21 updates lost)"
    assert _updates_lost_text(None) == ""
    # A file from before the update count was kept: the version alone still holds.
    second.version_path.write_text("41")
    assert Learner(cfg, spec, _NoLinks(), threading.Event()).restored_from["version"] == 42


def torch_equal(a, b) -> bool:
    import torch

    return bool(torch.equal(a, b))


def test_learner_checkpoint_on_an_unwritable_path_is_counted_not_fatal(tmp_path):
    from laneshift.actors.envs import spec_of
    from laneshift.learner.loop import Learner

    cfg = load_run_config(overrides={"env.scenario": "lka", "train.run_dir": str(tmp_path), "learner.hidden": "16"})
    learner = Learner(cfg, spec_of(cfg.env), _NoLinks(), threading.Event())
    (tmp_path / "checkpoints").write_text("a file where the directory should be")  # every write fails
    assert learner.checkpoint("latest") is None
    assert learner.save_state() is False
    learner.publish()
    assert learner.checkpoint_failures == 3


def test_a_second_replay_server_on_the_same_run_dir_is_refused(tmp_path):
    from laneshift.actors.envs import spec_of
    from laneshift.replay_server.service import ReplayServer

    cfg = load_run_config(overrides={"env.scenario": "lka", "train.run_dir": str(tmp_path)})
    first = ReplayServer(cfg, spec_of(cfg.env))
    first.checkpoint_dir = tmp_path / "replay_checkpoint"
    first._lock_checkpoint_dir()
    second = ReplayServer(cfg, spec_of(cfg.env))
    second.checkpoint_dir = tmp_path / "replay_checkpoint"
    with pytest.raises(ValueError, match="another replay server is using"):
        second._lock_checkpoint_dir()
    first.close()
    second._lock_checkpoint_dir()  # free again once the first one is gone
    second.close()


def test_zenoh_message_limit_is_sized_from_the_run():
    vector = load_run_config()
    assert vector.max_message_bytes == max(16 * 2**20, 2 * vector.largest_message_bytes) < 32 * 2**20
    gray = load_run_config(overrides={"env.observation": "grayscale"})
    assert gray.max_message_bytes == 2 * gray.largest_message_bytes > 256 * 2**20  # 4x100x100 frames
    assert load_run_config(overrides={"transport.max_message_mb": 64}).max_message_bytes == 64 * 2**20
    with pytest.raises(ConfigError, match="transport.max_message_mb"):
        load_run_config(overrides={"env.observation": "grayscale", "transport.max_message_mb": 8})


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_learner_core_pins_every_thread_of_a_component_process():
    """``deploy.learner_core``: the learner's threads (those running already and later ones) on that
    CPU alone, any other component's on the others; -1 leaves a process as it is. Run in child
    processes: pinning this test's own process would pin the rest of the suite."""
    import subprocess
    import sys

    code = ("import os, sys, threading, time\n"
            "from laneshift.deploy.pinning import pin_process\n"
            "ev = threading.Event(); t = threading.Thread(target=ev.wait); t.start()\n"
            "said = pin_process(int(sys.argv[1]), sys.argv[2] == 'learner')\n"
            "late = threading.Thread(target=lambda: print(sorted(os.sched_getaffinity(0)))); late.start(); late.join()\n"
            "print(sorted(os.sched_getaffinity(t.native_id))); print(said); ev.set()\n")
    cpus = sorted(os.sched_getaffinity(0))
    for who, want in (("learner", [cpus[0]]), ("w0", cpus[1:])):
        out = subprocess.run([sys.executable, "-c", code, str(cpus[0]), who], capture_output=True, text=True,
                             timeout=60, check=True).stdout.splitlines()
        assert out[0] == out[1] == str(want), out
        assert out[2].startswith(f"pinned to CPUs {want}")
    out = subprocess.run([sys.executable, "-c", code, "-1", "learner"], capture_output=True, text=True, timeout=60,
                         check=True).stdout.splitlines()
    assert out[0] == str(cpus) and out[2] == "None"


def test_learner_core_auto_is_the_last_cpu_in_local_mode_and_off_on_a_cluster(monkeypatch):
    """``deploy.learner_core`` -2 (the default): the launcher pins the learner to its machine's last
    CPU in local mode when it may use two or more, and to nothing on a cluster or on one CPU;
    -1 and an explicit CPU pass through."""
    from laneshift.config import load_run_config
    from laneshift.deploy.pinning import resolve_learner_core

    assert load_run_config().deploy.learner_core == -2
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 5}, raising=False)
    assert resolve_learner_core(-2, local=True) == 5
    assert resolve_learner_core(-2, local=False) == -1
    assert resolve_learner_core(-1, local=True) == -1 and resolve_learner_core(3, local=False) == 3
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert resolve_learner_core(-2, local=True) == -1
    with pytest.raises(ConfigError, match="deploy.learner_core"):
        load_run_config(overrides={"deploy.learner_core": -3})


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs 2 CPUs")
def test_local_mode_moves_the_launcher_and_its_processes_off_the_learners_cpu():
    """``pin_process_tree``: the launcher and every process below it (Ray's own, in local mode) but
    the skipped one (the learner's) go off the learner's CPU, threads included; a process started
    later by one of them inherits that, and a restarted learner's ``pin_process`` gets its CPU back. In a child process, so this
    test's own process keeps its CPUs."""
    import subprocess
    import sys

    code = ("import os, subprocess, sys, threading, time\n"
            "from laneshift.deploy.pinning import own_cpus, pin_process, pin_process_tree, restore_own_cpus\n"
            "core = int(sys.argv[1]); before = own_cpus()\n"
            "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'])\n"
            "learner_pid = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)'])\n"
            "ev = threading.Event(); t = threading.Thread(target=ev.wait); t.start()\n"
            "moved = pin_process_tree(core, skip={learner_pid.pid})\n"
            "late = subprocess.run([sys.executable, '-c', 'import os; print(sorted(os.sched_getaffinity(0)))'],\n"
            "                      capture_output=True, text=True).stdout.strip()\n"
            "learner = subprocess.run([sys.executable, '-c', 'from laneshift.deploy.pinning import pin_process; '\n"
            "                          'import os; pin_process(%d, True); print(sorted(os.sched_getaffinity(0)))' % core],\n"
            "                         capture_output=True, text=True).stdout.strip()\n"
            "print(moved); print(sorted(os.sched_getaffinity(child.pid))); print(sorted(os.sched_getaffinity(t.native_id)))\n"
            "print(late); print(learner); print(sorted(os.sched_getaffinity(learner_pid.pid)))\n"
            "restore_own_cpus(before); print(sorted(os.sched_getaffinity(t.native_id)))\n"
            "ev.set(); child.kill(); learner_pid.kill()\n")
    cpus = sorted(os.sched_getaffinity(0))
    out = subprocess.run([sys.executable, "-c", code, str(cpus[-1])], capture_output=True, text=True, timeout=120,
                         check=True).stdout.splitlines()
    others = str(cpus[:-1])
    assert int(out[0]) >= 2, out  # itself and its child
    assert out[1] == out[2] == out[3] == others, out
    assert out[4] == str([cpus[-1]]), out
    assert out[5] == str(cpus), out  # the skipped process (the learner's) keeps its CPUs
    assert out[6] == str(cpus), out  # and the launcher gets its CPUs back after the run, every thread


def test_the_envs_spec_comes_from_a_child_process_and_its_failure_is_one_line():
    """The launcher keeps no simulator: the spec is computed in a child (deploy.spec_process), and
    is the same as computed here; a config whose env cannot be built fails with its last line."""
    from laneshift.actors.envs import spec_of
    from laneshift.deploy.errors import LaunchError
    from laneshift.deploy.spec_process import SpecProcess
    from laneshift.envspec import spec_to_dict

    cfg = load_run_config(overrides={"env.scenario": "lka"})
    assert SpecProcess(cfg).result() == spec_to_dict(spec_of(cfg.env))
    bad = load_run_config(overrides={"env.scenario": "laneshift/NoSuchEnv-v0"})
    with pytest.raises(LaunchError, match=r"^the env's spec could not be computed: .*NoSuchEnv"):
        SpecProcess(bad).result()
