"""Faults against a real 2-worker local run: every component is a Ray actor that Ray restarts.

Each test kills one process with SIGKILL mid-run (found through ``<run dir>/logs/<name>.pid``)
and checks that the run completes, that the component came back, and that every transition a
worker made is either stored or counted as lost (``lost_items``), never silently missing. Also:
the launcher's SIGTERM and SIGKILL, the run-dir lock and refusal, and ``--resume``.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs.
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from laneshift.config import load_run_config
from laneshift.tools.chaos.faults import FAST, FAULTS
from laneshift.tools.chaos.runs import alive as _alive
from laneshift.tools.chaos.strikes import FaultInjector, checkpointing
from laneshift.deploy.processes import descendants as _descendants
from laneshift.deploy.local import train_local


def run_with_fault(tmp_path: Path, component: str, at_steps: int, total: int = 6000, extra=lambda: True,
                   when_stopped=None, **overrides):
    run_dir = tmp_path / "run"
    cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir), "train.env_steps": total, **overrides})
    killer = FaultInjector(run_dir, component, at_steps, ready=extra, when_stopped=when_stopped)
    killer.start()
    out = io.StringIO()
    rc = train_local(cfg, out=out)
    killer.stop()
    killer.join(1)
    text = out.getvalue()
    assert killer.killed_pid, f"{component} was never killed:\n{text}"
    assert rc == 0, text
    summary = json.loads((run_dir / "summary.json").read_text())
    replay = json.loads((run_dir / "replay_stats.json").read_text())
    assert f"{component} died" in text and "Ray restarted it" in text, text
    assert summary["restarts"] == {component: 1}, summary["restarts"]
    assert sum(w["env_steps"] for w in summary["workers"]) == total, summary["workers"]
    # Every transition made is stored or counted as lost: nothing silently missing.
    stored = replay["tables"]["online"]["inserted"]
    assert stored + summary["replay"]["lost_items"] == total, (stored, summary["replay"])
    return run_dir, summary, replay, text


def test_env_worker_killed_is_restarted_and_resumes_its_share(tmp_path):
    run_dir, summary, replay, _ = run_with_fault(tmp_path, "w1", at_steps=1500)
    w1 = next(w for w in summary["workers"] if w["name"] == "w1")
    assert w1["restarts"] == 1 and w1["resumed_at"] > 0  # went on from what the replay server had stored
    assert summary["replay"]["lost_items"] == 0  # a dying worker loses only unsent steps, which it redoes


def test_learner_killed_comes_back_from_its_state_with_a_higher_version(tmp_path):
    state = tmp_path / "run" / "checkpoints" / "learner_state.pt"
    since: list[float] = []

    def saved_after_training_began() -> bool:  # a state with updates in it, not the first empty one
        since.append(since[0] if since else time.time())
        return state.exists() and state.stat().st_mtime > since[0]

    # The chaos suite's learner fault settings (tools.chaos.faults.FAULTS): states often, workers held to
    # the learner, so a state with updates in it is written long before the budget is spent.
    run_dir, summary, replay, _ = run_with_fault(tmp_path, "learner", at_steps=1500, extra=saved_after_training_began,
                                                 **FAULTS["learner"]["overrides"])
    log = (run_dir / "logs" / "learner.log").read_text()
    assert "restored" in log and "restarted by Ray" in log
    # Versions never went backwards: every worker's versions, in the order it used them, only grow.
    for w in summary["workers"]:
        versions = [v for v, _ in w["version_runs"]]
        assert versions == sorted(versions), versions
    assert summary["learner"]["restored_from"]["updates"] > 0


def test_router_killed_comes_back_on_the_same_endpoint(tmp_path):
    # As its own actor (as on a cluster): a local run's router otherwise lives in the launcher.
    run_dir, summary, replay, text = run_with_fault(tmp_path, "router", at_steps=1500,
                                                    **{"deploy.router_in": "actor"})
    log = (run_dir / "logs" / "router.log").read_text()
    endpoints = {line.split("listening on ")[1].strip() for line in log.splitlines() if "listening on" in line}
    assert len(endpoints) == 1, log  # same endpoint after the restart: every client reconnected


def test_replay_server_without_its_log_killed_before_its_first_checkpoint_counts_every_loss(tmp_path):
    """replay.wal off and no checkpoint to restore: what it had stored is lost, and counted (it
    used to read 0 lost). The workers send again the batches they had not seen acknowledged; the
    ones they had are gone, each counted whole (made == stored + lost is checked by run_with_fault).
    The kill comes at half the budget, after each worker's first acknowledgement (it asks every
    ACK_EVERY = 16 batches of 50 items, 800 of its env steps): before it, every batch is still in the
    workers' hands and a fast machine's run loses nothing, which is not what this test is about."""
    run_dir, summary, replay, text = run_with_fault(tmp_path, "replay-server", at_steps=3000,
                                                    **{"replay.checkpoint_every_s": 0, "replay.wal": "off"})
    lost = summary["replay"]
    assert lost["lost_items"] > 0 and lost["lost_items"] == lost["lost_batches"] * FAST["actor.send_every"], lost


def assert_nothing_lost(summary: dict, replay: dict) -> None:
    """The write-ahead log keeps what the server took, the workers' resend what was on its way:
    a kill -9 of the replay server loses nothing (made == stored is checked by run_with_fault)."""
    lost = summary["replay"]
    assert lost["lost_batches"] == 0 and lost["lost_items"] == 0, lost
    assert replay["rejected"] == {}, replay["rejected"]


def test_replay_server_killed_early_comes_back_from_its_log_alone(tmp_path):
    """No checkpoint yet (none on a timer): the log brings back every batch the server took."""
    run_dir, summary, replay, text = run_with_fault(tmp_path, "replay-server", at_steps=600,
                                                    **{"replay.checkpoint_every_s": 0})
    log = (run_dir / "logs" / "replay-server.log").read_text()
    assert "from the write-ahead log" in log and "restored" not in log, log
    assert_nothing_lost(summary, replay)


def test_replay_server_killed_after_a_checkpoint_restores_it(tmp_path):
    meta = tmp_path / "run" / "replay_checkpoint" / "meta.json"
    run_dir, summary, replay, text = run_with_fault(
        tmp_path, "replay-server", at_steps=3000, extra=lambda: meta.exists() and json.loads(meta.read_text())["items"] >= 500,
        **{"replay.checkpoint_every_s": 0.5})
    log = (run_dir / "logs" / "replay-server.log").read_text()
    assert "restored" in log
    assert_nothing_lost(summary, replay)


def test_replay_server_killed_near_the_end_loses_nothing(tmp_path):
    """At 90 % of the budget: the workers may spend theirs while the server is down; each waits
    until the restarted server holds all it sent, sending again what it lacks."""
    run_dir, summary, replay, text = run_with_fault(tmp_path, "replay-server", at_steps=5400,
                                                    **{"replay.checkpoint_every_s": 0.5})
    assert_nothing_lost(summary, replay)


def test_replay_server_killed_while_writing_a_checkpoint_loses_nothing(tmp_path):
    """Checkpoints back to back; the server is stopped (SIGSTOP) until one is seen in the middle of
    its copy with batches logged after the last whole one's cut (``checkpointing``), then killed:
    the restart restores the last whole one and replays the log after its cut, so the batches the
    copy caught in part are all back (they used to be dropped, or lost uncounted)."""
    run_dir = tmp_path / "run"
    run_dir_, summary, replay, text = run_with_fault(
        tmp_path, "replay-server", at_steps=2000, extra=lambda: (run_dir / "replay_checkpoint" / "meta.json").exists(),
        when_stopped=checkpointing(run_dir), **FAULTS["replay-during-checkpoint"]["overrides"])
    log = (run_dir / "logs" / "replay-server.log").read_text()
    replayed = re.search(r"replayed (\d+) batches \(\d+ items\) from the write-ahead log", log)
    assert "a checkpoint the previous process died writing" in log and replayed and int(replayed[1]) > 0, log
    # While the server was stopped the workers went on sending (up to their window of 64
    # unacknowledged batches each); what the router queued for it died with it, and came again
    # from the workers' buffers.
    assert_nothing_lost(summary, replay)


def test_a_service_killed_as_the_workers_finish_is_still_counted(tmp_path, monkeypatch):
    """The race CI met: the replay server died in the run's last moments, after the workers'
    results were in but before ``ray.wait`` saw its run() fail, and the summary read "restarts
    none". Here the kill lands exactly there; the sweep before the stop must find it by its pid."""
    from laneshift.deploy.supervision import Run

    run_dir = tmp_path / "run"
    sweep, killed = Run._sweep_services, []

    def kill_then_sweep(self: Run) -> None:
        pid = int((run_dir / "logs" / "replay-server.pid").read_text())
        os.kill(pid, signal.SIGKILL)
        killed.append(pid)
        sweep(self)

    monkeypatch.setattr(Run, "_sweep_services", kill_then_sweep)
    total = 3000
    cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir), "train.env_steps": total})
    out = io.StringIO()
    assert train_local(cfg, out=out) == 0, out.getvalue()
    text = out.getvalue()
    summary = json.loads((run_dir / "summary.json").read_text())
    replay = json.loads((run_dir / "replay_stats.json").read_text())
    assert killed and "replay-server died" in text, text
    assert summary["restarts"] == {"replay-server": 1}, summary["restarts"]
    stored = replay["tables"]["online"]["inserted"]
    assert stored + summary["replay"]["lost_items"] == total, (stored, summary["replay"])


def test_a_used_run_dir_is_refused_and_a_second_launcher_too(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("{}\n")
    out = io.StringIO()
    cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir)})
    assert train_local(cfg, out=out) == 1
    assert "already holds a run" in out.getvalue() and "--resume" in out.getvalue()

    from laneshift.deploy.errors import LaunchError
    from laneshift.deploy.run_dir import RunDirLock

    other = tmp_path / "other"
    with pytest.raises(LaunchError, match="in use by another"):
        held = RunDirLock(other).acquire()
        try:
            RunDirLock(other).acquire()
        finally:
            held.release()


def _launcher(tmp_path: Path, *extra: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "laneshift", "train", "--local", "--workers", "2", "--scenario", "lka",
           "--run-dir", str(tmp_path / "run"), "--set", "train.log_every_s=0.2", "--set", "learner.log_every_s=0.2",
           "--set", "learner.hidden=32",
           "--set", "train.eval_episodes=0", "--set", "learner.checkpoint_every_s=1", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def _wait_training(proc: subprocess.Popen, timeout_s: float = 120) -> list[str]:
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            break
        lines.append(line)
        if " upd " in line and "steps       0/" not in line:
            return lines
    pytest.fail("training never started:\n" + "".join(lines))


def test_sigterm_ends_gracefully_and_resume_finishes_the_budget(tmp_path):
    """SIGTERM (what `ray job stop`, systemd and Kubernetes send): checkpoints and a summary, no
    process left; then `--resume` goes on from there and spends exactly the rest of the budget."""
    # A budget the signal lands inside: a fast machine spent 6,000 lka steps before the first
    # progress line (the learner then logged once a second) and the SIGTERM met a finished run.
    budget = 20_000
    proc = _launcher(tmp_path, "--env-steps", str(budget))
    try:
        lines = _wait_training(proc)
        family = _descendants(proc.pid)
        proc.send_signal(signal.SIGTERM)
        rest, _ = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = "".join(lines) + rest
    assert proc.returncode == 143, text
    assert "SIGTERM received; stopping gracefully" in text
    run_dir = tmp_path / "run"
    first = json.loads((run_dir / "summary.json").read_text())
    assert first["ended_by"] == "SIGTERM"
    assert (run_dir / "checkpoints" / "learner_state.pt").exists()
    assert (run_dir / "replay_checkpoint" / "meta.json").exists()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(_alive(p) for p in family):
        time.sleep(0.2)
    assert not [p for p in family if _alive(p)], "processes left behind"
    done_before = sum(w["env_steps"] for w in first["workers"])
    assert 0 < done_before < budget

    resumed = subprocess.run([sys.executable, "-m", "laneshift", "train", "--local", "--resume", str(run_dir)],
                             capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    second = json.loads((run_dir / "summary.json").read_text())
    assert sum(w["env_steps"] for w in second["workers"]) == budget
    assert {w["name"]: w["resumed_at"] for w in second["workers"]} == {
        w["name"]: w["env_steps"] for w in first["workers"]}
    assert second["learner"]["restored_from"]["version"] > first["learner"]["version"]


def test_launcher_killed_leaves_no_process_and_no_temp_dir(tmp_path):
    proc = _launcher(tmp_path, "--env-steps", "10000000")
    try:
        _wait_training(proc)
        family = _descendants(proc.pid)
        assert len(family) >= 5, family
        tmp_dirs = {p for p in Path(os.environ.get("TMPDIR", "/tmp")).glob("lsray-*")
                    if any(str(p) in _cmdline(pid) for pid in family)}
        proc.kill()
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and (any(_alive(p) for p in family) or any(d.exists() for d in tmp_dirs)):
        time.sleep(0.2)
    assert not [p for p in family if _alive(p)], [(p, _cmdline(p)[:80]) for p in family if _alive(p)]
    assert not [d for d in tmp_dirs if d.exists()]


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def test_the_router_runs_in_a_local_launcher_and_as_an_actor_on_a_cluster():
    """``deploy.router_in``: auto puts a local run's router in the launcher (whose death ends a
    local run anyway) and a cluster run's in its own actor; the launcher is refused on a cluster."""
    from laneshift.deploy.errors import LaunchError
    from laneshift.deploy.stop_signals import StopSignals
    from laneshift.deploy.supervision import Run

    def in_launcher(local: bool, **overrides) -> bool:
        return Run(load_run_config(overrides=overrides), local=local, out=io.StringIO(),
                   signals=StopSignals())._router_in_launcher()

    assert in_launcher(True) and not in_launcher(False)
    assert not in_launcher(True, **{"deploy.router_in": "actor"})
    with pytest.raises(LaunchError, match="needs a local run"):
        in_launcher(False, **{"deploy.router_in": "launcher"})
