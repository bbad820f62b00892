"""``laneshift chaos``: the fault suite. Each fault against a real 2-worker local run.

What it is: one training run per fault, each with the fault injected at a fixed point of the
run, and one table row per fault: survived, recovery seconds, transitions made / stored /
counted lost, weights versions monotonic, demo shard bytes identical, processes left behind.
``tests/test_faults.py`` runs the same faults (with ``FaultInjector``) as fast tests.
Room: the tools (the fault suite, beside the wiring it strikes). May import: the contract and ``deploy``.

    laneshift chaos --faults worker,learner,router,replay,replay-after-checkpoint,replay-during-checkpoint --json
    laneshift chaos --faults disk-full,unwritable,stats-flood,launcher-sigterm,launcher-kill

The link rows (``link-reset``, ``link-cut``, ``slow-link``) put a TCP proxy (``linkproxy``) between
the workers and the router; a cut between two hosts (two network namespaces, root) runs as
``pytest -m chaos tests/test_network_faults.py``.

Processes are found through ``<run dir>/logs/<component>.pid`` (each actor writes its own).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from laneshift.config import load_run_config

from laneshift.deploy.processes import descendants

#: A small, fast run with every mechanism on (LKA plant: seconds per thousand steps).
FAST = {"env.scenario": "lka", "actor.workers": 2, "actor.send_every": 50, "actor.epsilon_decay_steps": 1000,
        "learner.hidden": "64,64", "learner.batch_size": 64, "learner.publish_every": 10,
        "learner.checkpoint_every": 100, "learner.checkpoint_every_s": 1.0, "replay.samples_per_insert": 8,
        "replay.spi_tolerance": 1024, "replay.min_size": 200, "train.eval_episodes": 0,
        # A fault strikes once metrics.jsonl shows its step count: the learner logs it every 0.1 s
        # (learner.log_every_s), so on a fast machine (CI: 650 to 4,000 steps within 0.5 s; here 600
        # to 5,650 within one 1 s interval) it still lands mid-run; the launcher polls as often.
        "learner.log_every_s": 0.1, "train.log_every_s": 0.1,
        # No learner CPU of its own (the local default): with it this small run spends its whole
        # budget in about 1.5 s of training, before a fault's precondition (a checkpoint, a state
        # saved after training began) can hold; three fault tests then raced the run's end.
        "deploy.learner_core": -1}


def logged_env_steps(run_dir: Path) -> tuple[int, int]:
    """The newest (env steps, updates) the learner logged in ``metrics.jsonl`` ((0, 0) before any)."""
    try:
        lines = (run_dir / "metrics.jsonl").read_text().splitlines()
    except OSError:
        return 0, 0
    for line in reversed(lines):
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if rec.get("kind") == "learner" and "env_steps" in rec:
            return int(rec["env_steps"]), int(rec.get("updates", 0))
    return 0, 0


def _wait_until(condition: Callable[[], bool], deadline: float, halt: threading.Event, period_s: float = 0.05) -> bool:
    """Poll ``condition`` until it holds (True), or the deadline passes or ``halt`` is set (False)."""
    while time.monotonic() < deadline and not halt.is_set():
        if condition():
            return True
        time.sleep(period_s)
    return False


def _recovery_s(run_dir: Path, before: tuple[int, int], since: float, deadline: float,
                halt: threading.Event) -> float | None:
    """Seconds from ``since`` until env steps and learner updates are both past ``before``: a
    learner that died shows recovery only once it updates again (actors may go on meanwhile)."""

    def moved() -> bool:
        steps, updates = logged_env_steps(run_dir)
        return steps > before[0] and updates > before[1]

    return round(time.monotonic() - since, 1) if _wait_until(moved, deadline, halt, 0.1) else None


def checkpointing(run_dir: Path) -> Callable[[], bool]:
    """True while the replay server is writing a checkpoint (its temp dir exists until the rename)."""
    return lambda: (run_dir / "replay_checkpoint.tmp").is_dir()


def _reached(run_dir: Path, steps: int) -> Callable[[], bool]:
    return lambda: logged_env_steps(run_dir)[0] >= steps


@dataclass(eq=False)  # a Thread must stay hashable
class FaultInjector(threading.Thread):
    """Sends ``sig`` to ``component``'s process once the run has made ``at_steps`` env steps and
    ``ready()`` holds; then measures recovery: seconds until env steps (and updates) move again."""

    run_dir: Path
    component: str
    at_steps: int
    ready: Callable[[], bool] = lambda: True
    # If set: once ready, the process is stopped (SIGSTOP) and this is checked while it cannot
    # move; the signal is sent only if it holds (else SIGCONT, and again 50 ms later). For a state
    # that lasts a moment, such as a checkpoint being written.
    when_stopped: Callable[[], bool] | None = None
    stops: int = 0  # SIGSTOPs sent for when_stopped
    sig: int = signal.SIGKILL
    timeout_s: float = 300.0
    killed_pid: int | None = None
    killed_at: float | None = None
    recovery_s: float | None = None
    _halt: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        threading.Thread.__init__(self, daemon=True, name=f"inject-{self.component}")

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout_s
        pid_file = self.run_dir / "logs" / f"{self.component}.pid"
        reached = _reached(self.run_dir, self.at_steps)
        if not _wait_until(lambda: pid_file.exists() and reached() and self.ready(), deadline, self._halt):
            return
        before = logged_env_steps(self.run_dir)
        pid = int(pid_file.read_text())
        if self.when_stopped is not None:
            # Seen from outside first (no stop), then again with the process stopped, and the
            # signal sent at once: batches sent while it is stopped are lost with it, so the stop
            # lasts three system calls. (Once kill() returns every thread has the stop pending and
            # runs no more user code; a system call in progress, a few microseconds, may end.)
            while True:
                if not _wait_until(self.when_stopped, deadline, self._halt, 0.001):
                    return
                os.kill(pid, signal.SIGSTOP)
                self.stops += 1
                if self.when_stopped():
                    break
                os.kill(pid, signal.SIGCONT)
        os.kill(pid, self.sig)
        if self.when_stopped is not None and self.sig != signal.SIGKILL:
            os.kill(pid, signal.SIGCONT)
        self.killed_pid, self.killed_at = pid, time.monotonic()
        self.recovery_s = _recovery_s(self.run_dir, before, self.killed_at, deadline, self._halt)

    @property
    def struck(self) -> bool:
        return self.killed_pid is not None

    def stop(self) -> None:
        self._halt.set()


def _digest(paths: list[str]) -> str:
    h = hashlib.sha256()
    for root in sorted(paths):
        for p in sorted(Path(root).rglob("*")):
            if p.is_file():
                h.update(p.read_bytes())
    return h.hexdigest()


def alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie waiting for its parent counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _ray_processes(run_dir: Path) -> list[int]:
    """Processes still holding a file of this run open (actors log into the run dir)."""
    left = []
    for q in os.listdir("/proc"):
        if not q.isdigit() or int(q) == os.getpid():
            continue
        try:
            fds = [os.readlink(f"/proc/{q}/fd/{f}") for f in os.listdir(f"/proc/{q}/fd")]
        except OSError:
            continue
        if any(f.startswith(str(run_dir) + "/") for f in fds):
            left.append(int(q))
    return left


FAULTS: dict[str, dict] = {
    "worker": {"component": "w1"},
    # The kill waits for a learner state saved after training began; on a fast machine the whole
    # budget could be spent before one was (the learner alone on its core makes ~340 updates/s
    # here), so states come 4x as often and the replay ratio holds the workers to the learner.
    "learner": {"component": "learner", "needs": "learner_state",
                "overrides": {"learner.checkpoint_every_s": 0.25, "replay.samples_per_insert": 32}},
    # A local run's router lives in the launcher (deploy.router_in auto): killing it is the launcher's
    # row. This row runs the router as its own actor, as on a cluster, and kills that.
    "router": {"component": "router", "overrides": {"deploy.router_in": "actor"}},
    # The replay server: before any checkpoint (its write-ahead log alone brings the table back),
    # once one exists, in the middle of one (checkpoints back to back: the kill lands while one is
    # being copied), and without the log (what arrived since the last checkpoint is lost, counted).
    "replay": {"component": "replay-server", "overrides": {"replay.checkpoint_every_s": 0}},
    "replay-after-checkpoint": {"component": "replay-server", "needs": "replay_checkpoint",
                                "overrides": {"replay.checkpoint_every_s": 0.5}},
    "replay-during-checkpoint": {"component": "replay-server", "needs": "replay_checkpoint", "while": "checkpointing",
                                 "overrides": {"replay.checkpoint_every_s": 0.02, "replay.capacity": 10_000}},
    "replay-no-wal": {"component": "replay-server", "overrides": {"replay.checkpoint_every_s": 0, "replay.wal": "off"}},
    # The replay server at other points of the budget (a checkpoint every 0.5 s): near the end the
    # workers spend theirs while it is down, and wait until the restarted one holds all they sent.
    **{f"replay-at-{pct}": {"component": "replay-server", "at": pct / 100,
                            "overrides": {"replay.checkpoint_every_s": 0.5}} for pct in (10, 50, 90)},
    # The run dir on a 6 MiB tmpfs that fills up: checkpoints fail (counted, retried), training goes on.
    "disk-full": {"disk_mb": 6, "overrides": {"replay.checkpoint_every_s": 2, "replay.capacity": 60_000}},
    # The run dir read-only from an eighth to half of the budget (at most 10 s): over before the run ends (a bind mount remounted ro: EROFS even for root), then writable again.
    "unwritable": {"read_only_s": 10.0, "overrides": {"replay.checkpoint_every_s": 1}},
    # 5,000 actor names, one one-row batch each, from a foreign client, while stats are queried.
    "stats-flood": {"flood_actors": 5000},
    # The link between the workers and the router (a proxy in front of it, deploy.worker_router):
    # every connection reset at a quarter, half and three quarters of the budget; a 10 s cut (the
    # proxy holds every byte, no connection closes) at a quarter; a slow, jittery link (50 +- 20 ms
    # per chunk each way) for the whole run, reset at half. The workers' resend must lose nothing.
    "link-reset": {"link": {"resets_at": (0.25, 0.5, 0.75)}},
    "link-cut": {"link": {"hold_at": 0.25, "hold_s": 10.0}},
    "slow-link": {"link": {"latency_s": 0.05, "jitter_s": 0.02, "resets_at": (0.5,)}},
    # The launcher itself: SIGTERM (`ray job stop`, systemd, Kubernetes) or kill -9, then
    # `laneshift train --resume RUN_DIR`, which must spend exactly the rest of the budget.
    "launcher-sigterm": {"launcher_signal": signal.SIGTERM, "overrides": {"replay.checkpoint_every_s": 2}},
    "launcher-kill": {"launcher_signal": signal.SIGKILL, "overrides": {"replay.checkpoint_every_s": 2}},
}


def run_fault(name: str, work: Path, env_steps: int, demos: str | None) -> dict:
    spec = FAULTS[name]
    run_dir = work / name / "run"
    shutil.rmtree(work / name, ignore_errors=True)  # this suite's own scratch: every fault starts fresh
    if spec.get("disk_mb"):
        return _disk_full(name, spec, work / name, env_steps)
    if spec.get("launcher_signal"):
        return _launcher_fault(name, spec, run_dir, env_steps)
    overrides = {**FAST, "train.run_dir": str(run_dir), "train.env_steps": env_steps, **spec.get("overrides", {})}
    proxy = None
    if spec.get("link"):  # the workers reach the router through a proxy that strikes the link
        from laneshift.transport import free_tcp_port

        from laneshift.deploy.linkproxy import LinkProxy

        router_port = free_tcp_port()
        proxy = LinkProxy(router_port, latency_s=spec["link"].get("latency_s", 0.0),
                          jitter_s=spec["link"].get("jitter_s", 0.0), reset_every_s=0).start()
        overrides.update({"deploy.router_port": router_port, "deploy.worker_router": proxy.endpoint})
    if demos:
        overrides.update({"replay.demo_mode": "retention", "replay.demo_paths": demos, "replay.capacity": 9_000})
    cfg = load_run_config(overrides=overrides)
    since: list[float] = []

    def ready() -> bool:
        since.append(since[0] if since else time.time())
        need = spec.get("needs")
        if need == "learner_state":
            p = run_dir / "checkpoints" / "learner_state.pt"
            return p.exists() and p.stat().st_mtime > since[0]
        if need == "replay_checkpoint":
            return (run_dir / "replay_checkpoint" / "meta.json").exists()
        return True

    demo_before = _digest([demos]) if demos else ""
    if spec.get("read_only_s"):
        inject = ReadOnlyRunDir(run_dir, at_steps=env_steps // 8, until_steps=env_steps // 2, seconds=spec["read_only_s"])
    elif spec.get("flood_actors"):
        inject = StatsFlood(run_dir, at_steps=env_steps // 4, actors=spec["flood_actors"])
    elif proxy is not None:
        link = spec["link"]
        inject = LinkFault(run_dir, proxy, resets_at=[int(env_steps * f) for f in link.get("resets_at", ())],
                           hold_at=int(env_steps * link["hold_at"]) if "hold_at" in link else None,
                           hold_s=link.get("hold_s", 0.0))
    else:
        inject = FaultInjector(run_dir, spec["component"], at_steps=int(env_steps * spec.get("at", 0.25)), ready=ready,
                               when_stopped=checkpointing(run_dir) if spec.get("while") == "checkpointing" else None)
    inject.start()
    from laneshift.deploy.local import train_local

    out = io.StringIO()
    started = time.monotonic()
    try:
        rc = train_local(cfg, out=out)
    finally:
        inject.stop()
        if proxy is not None:
            proxy.stop()
    row: dict = {"fault": name, "rc": rc, "wall_s": round(time.monotonic() - started, 1),
                 "injected": inject.struck, "recovery_s": inject.recovery_s,
                 **({"stops": inject.stops} if getattr(inject, "when_stopped", None) else {})}
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        replay = json.loads((run_dir / "replay_stats.json").read_text())
    except (OSError, json.JSONDecodeError):
        return {**row, "survived": False, "log_tail": out.getvalue()[-2000:]}
    made, stored, lost = _accounting(summary, replay)
    time.sleep(2)  # let Ray's processes exit before counting what is left
    row.update({"survived": rc == 0 and made == env_steps, "restarts": summary.get("restarts", {}),
                "made": made, "stored": stored, "lost_counted": lost, "unaccounted": made - stored - lost,
                "versions_monotonic": _monotonic(summary),
                "demo_identical": (_digest([demos]) == demo_before) if demos else None,
                "left_behind": len(_ray_processes(run_dir))})
    if spec.get("read_only_s"):  # the fault must have struck: writes failed, counted, and training went on
        row["write_failures_counted"] = failures = _write_failures(summary, replay)
        row["survived"] = row["survived"] and inject.struck and sum(failures.values()) > 0
    if proxy is not None:  # every strike landed, while the run went on, and nothing was lost
        stats = proxy.stats.as_dict()
        row["link"] = {k: stats[k] for k in ("connections", "resets", "bytes_up", "bytes_down",
                                             "delay_ms_min_mean_max")}
        row["link"]["strikes"] = inject.done
        row["survived"] = row["survived"] and inject.struck
    if spec.get("flood_actors"):
        row.update(inject.report())
        row["survived"] = (row["survived"] and inject.struck and not summary.get("restarts")
                           and inject.stats_answered == inject.stats_asked)
    return row


def _accounting(summary: dict, replay: dict) -> tuple[int, int, int]:
    """(made, stored, counted lost) of the run's own env workers (a foreign client's items aside)."""
    names = {w["name"] for w in summary["workers"]}
    made = sum(w["env_steps"] for w in summary["workers"])
    actors = replay.get("actors", {})
    if names <= set(actors):
        stored = sum(int(actors[n]["stored"]) for n in names)
        # Counted by the server, plus what a worker sent after the last batch the server saw.
        lost = sum(int(actors[w["name"]]["lost_items"]) + max(0, w["env_steps"] - int(actors[w["name"]]["env_steps"]))
                   for w in summary["workers"])
    else:
        stored, lost = int(replay["tables"]["online"]["inserted"]), int(summary["replay"]["lost_items"])
    return made, stored, lost


def _monotonic(summary: dict) -> bool:
    return all([v for v, _ in w["version_runs"]] == sorted(v for v, _ in w["version_runs"]) for w in summary["workers"])


def _write_failures(summary: dict, replay: dict) -> dict[str, int]:
    return {"replay_checkpoint": int((replay.get("checkpoint") or {}).get("failures", 0)),
            "learner": int(summary["learner"].get("checkpoint_failures", 0))}


@dataclass(eq=False)
class LinkFault(threading.Thread):
    """Strikes the workers' link through ``proxy`` once the run has made each of ``resets_at`` env
    steps (every live connection reset) and ``hold_at`` (a cut of ``hold_s``: nothing moves, no
    connection closes); recovery is measured from the last strike (from the end of a cut)."""

    run_dir: Path
    proxy: Any
    resets_at: list[int]
    hold_at: int | None = None
    hold_s: float = 0.0
    timeout_s: float = 300.0
    done: list[str] = field(default_factory=list)
    recovery_s: float | None = None
    _halt: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        threading.Thread.__init__(self, daemon=True, name="inject-link")

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout_s
        plan = sorted([(at, "reset") for at in self.resets_at]
                      + ([(self.hold_at, "cut")] if self.hold_at is not None else []))
        for at, what in plan:
            if not _wait_until(lambda: _reached(self.run_dir, at)() and bool(self.proxy.live()), deadline, self._halt):
                return
            if what == "reset":
                resets = [self.proxy.reset_one() for _ in self.proxy.live()]
                self.done.append(f"reset {sum(r is not None for r in resets)} at {at}")
            else:
                self.proxy.hold(self.hold_s)
                self._halt.wait(self.hold_s)
                self.done.append(f"cut {self.hold_s:g} s at {at}")
            before, since = logged_env_steps(self.run_dir), time.monotonic()
        self.recovery_s = _recovery_s(self.run_dir, before, since, deadline, self._halt)

    @property
    def struck(self) -> bool:
        return len(self.done) == len(self.resets_at) + (self.hold_at is not None)

    def stop(self) -> None:
        self._halt.set()


@dataclass(eq=False)
class ReadOnlyRunDir(threading.Thread):
    """Makes the run dir read-only once the run made ``at_steps`` env steps, until ``until_steps``
    (at most ``seconds``): a bind mount of it onto itself, remounted ro (EROFS even for root; files
    already open keep writing, as on a filesystem remounted read-only under a running job), then
    unmounted, so the run ends on a writable dir and its summary shows what was counted."""

    run_dir: Path
    at_steps: int
    until_steps: int  # writable again once the run made this many env steps, or after ``seconds``
    seconds: float
    timeout_s: float = 300.0
    struck: bool = False
    recovery_s: float | None = None
    error: str = ""
    _halt: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        threading.Thread.__init__(self, daemon=True, name="inject-read-only")

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout_s
        if not _wait_until(_reached(self.run_dir, self.at_steps), deadline, self._halt):
            return
        where = str(self.run_dir)
        bound = subprocess.run(["mount", "--bind", where, where], capture_output=True, text=True)
        if bound.returncode != 0:
            self.error = bound.stderr.strip()
            return
        try:
            ro = subprocess.run(["mount", "-o", "remount,bind,ro", where], capture_output=True, text=True)
            self.struck = ro.returncode == 0
            self.error = ro.stderr.strip()
            _wait_until(_reached(self.run_dir, self.until_steps), time.monotonic() + self.seconds, self._halt)
        finally:
            subprocess.run(["umount", "-l", where], check=False)
        before, back = logged_env_steps(self.run_dir), time.monotonic()
        self.recovery_s = _recovery_s(self.run_dir, before, back, deadline, self._halt)

    def stop(self) -> None:
        self._halt.set()


@dataclass(eq=False)
class StatsFlood(threading.Thread):
    """A foreign zenoh client, once the run made ``at_steps`` env steps: one one-row batch under each
    of ``actors`` names (more than the replay server keeps state for), then stats queries. The
    learner, the launcher and every stats reply must come through it."""

    run_dir: Path
    at_steps: int
    actors: int
    timeout_s: float = 300.0
    struck: bool = False
    recovery_s: float | None = None
    stats_asked: int = 0
    stats_answered: int = 0
    largest_reply: int = 0
    _halt: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        threading.Thread.__init__(self, daemon=True, name="inject-stats-flood")

    def run(self) -> None:
        import numpy as np

        from laneshift import transport, wire
        from laneshift.actors.envs import spec_of

        deadline = time.monotonic() + self.timeout_s
        if not _wait_until(_reached(self.run_dir, self.at_steps), deadline, self._halt):
            return
        cfg = load_run_config(self.run_dir / "config.yaml")  # as the launcher resolved it: the router's endpoint
        schema = spec_of(cfg.env).schema
        obs = np.zeros((1, *schema.obs_shape), schema.obs_dtype)
        before, began = logged_env_steps(self.run_dir), time.monotonic()
        with transport.open_session(cfg.transport, "client", cfg.max_message_bytes) as session:
            for i in range(self.actors):
                name = f"flood{i:05d}"
                batch = wire.TransitionBatch.from_arrays(
                    actor=name, seq=0, weights_version=0, phase=0, env_steps=1, obs=obs, action=np.zeros(1),
                    reward=np.zeros(1), next_obs=obs, terminated=np.zeros(1), truncated=np.zeros(1))
                session.put(wire.transitions_key(cfg.transport.run_id, name), wire.encode_transitions(batch),
                            congestion_control=transport.zenoh.CongestionControl.BLOCK)
            self.struck = True
            for _ in range(10):
                self.stats_asked += 1
                reply = transport.query_ok(session, wire.replay_stats_key(cfg.transport.run_id), b"{}", 10.0)
                if isinstance(reply, (bytes, bytearray)):
                    self.stats_answered += 1
                    self.largest_reply = max(self.largest_reply, len(reply))
                time.sleep(0.2)
        self.recovery_s = _recovery_s(self.run_dir, before, began, deadline, self._halt)

    def report(self) -> dict:
        return {"flood_actors": self.actors, "stats_answered": f"{self.stats_answered}/{self.stats_asked}",
                "largest_stats_reply_bytes": self.largest_reply}

    def stop(self) -> None:
        self._halt.set()


def _launcher_fault(name: str, spec: dict, run_dir: Path, env_steps: int) -> dict:
    """The launcher as its own process, signalled at a quarter of the budget; then ``--resume``."""
    overrides = {**FAST, "train.env_steps": env_steps, **spec.get("overrides", {})}
    sets = [arg for k, v in overrides.items() for arg in ("--set", f"{k}={v}")]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    log = run_dir.parent / "launcher.log"
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with log.open("w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "laneshift", "train", "--local", "--run-dir", str(run_dir), *sets],
                                stdout=out, stderr=subprocess.STDOUT, env=env)
        row: dict = {"fault": name, "injected": False, "recovery_s": None}
        try:
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline and proc.poll() is None and logged_env_steps(run_dir)[0] < env_steps // 4:
                time.sleep(0.05)
            family = descendants(proc.pid)
            signalled = time.monotonic()
            proc.send_signal(spec["launcher_signal"])
            row["injected"] = True
            first_rc = proc.wait(120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and any(alive(p) for p in family):
        time.sleep(0.2)
    left_after_fault = [p for p in family if alive(p)]
    row.update({"first_rc": first_rc, "stopped_s": round(time.monotonic() - signalled, 1),
                "left_after_fault": len(left_after_fault)})
    resumed_at = time.monotonic()
    before = logged_env_steps(run_dir)  # where the stopped run's last record left it (the final one on SIGTERM)
    with log.open("a") as out:
        again = subprocess.Popen([sys.executable, "-m", "laneshift", "train", "--local", "--resume", str(run_dir)],
                                 stdout=out, stderr=subprocess.STDOUT, env=env)
        try:
            while again.poll() is None and time.monotonic() - resumed_at < 600:
                steps, updates = logged_env_steps(run_dir)
                if row["recovery_s"] is None and updates > before[1]:
                    # From the resume command until the learner trains past where it stopped (Ray's
                    # start included). Not env steps: the learner's count of them is rebuilt from
                    # the workers' episode reports, which take an episode each to arrive.
                    row["recovery_s"] = round(time.monotonic() - resumed_at, 1)
                time.sleep(0.1)
            rc = again.wait(10)
        finally:
            if again.poll() is None:
                again.kill()
                again.wait()
    row.update({"rc": rc, "wall_s": round(time.monotonic() - started, 1)})
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
        replay = json.loads((run_dir / "replay_stats.json").read_text())
    except (OSError, json.JSONDecodeError):
        return {**row, "survived": False, "log_tail": log.read_text()[-2000:]}
    made, stored, lost = _accounting(summary, replay)
    expected_rc = 143 if spec["launcher_signal"] == signal.SIGTERM else -signal.SIGKILL
    time.sleep(2)
    row.update({"survived": first_rc == expected_rc and rc == 0 and made == env_steps and not left_after_fault,
                "made": made, "stored": stored, "lost_counted": lost, "unaccounted": made - stored - lost,
                "versions_monotonic": _monotonic(summary), "demo_identical": None,
                "left_behind": len(left_after_fault) + len(_ray_processes(run_dir)),
                "resumed_at": {w["name"]: w.get("resumed_at", 0) for w in summary["workers"]}})
    return row


def _disk_full(name: str, spec: dict, where: Path, env_steps: int) -> dict:
    """A whole run whose run dir is a small tmpfs (root and mount needed; else the row says why)."""
    where.mkdir(parents=True)
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={spec['disk_mb']}m", "tmpfs", str(where)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        return {"fault": name, "survived": None, "skipped": f"cannot mount a tmpfs: {mounted.stderr.strip()}"}
    try:
        run_dir = where / "run"
        cfg = load_run_config(overrides={**FAST, "train.run_dir": str(run_dir), "train.env_steps": env_steps,
                                         **spec.get("overrides", {})})
        from laneshift.deploy.local import train_local

        out = io.StringIO()
        started = time.monotonic()
        rc = train_local(cfg, out=out)
        summary = json.loads((run_dir / "summary.json").read_text())
        replay = json.loads((run_dir / "replay_stats.json").read_text())
        made = sum(w["env_steps"] for w in summary["workers"])
        stored, lost = int(replay["tables"]["online"]["inserted"]), int(summary["replay"]["lost_items"])
        failures = _write_failures(summary, replay)
        time.sleep(2)
        return {"fault": name, "rc": rc, "wall_s": round(time.monotonic() - started, 1), "injected": True,
                "recovery_s": 0.0, "survived": rc == 0 and made == env_steps and sum(failures.values()) > 0,
                "made": made, "stored": stored, "lost_counted": lost, "unaccounted": made - stored - lost,
                "versions_monotonic": True, "demo_identical": None, "left_behind": len(_ray_processes(run_dir)),
                "write_failures_counted": failures, "restarts": summary.get("restarts", {})}
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def render(rows: list[dict]) -> str:
    head = f"{'fault':<26}{'survived':>9}{'recovery s':>11}{'made':>8}{'stored':>8}{'lost':>6}{'unacc.':>7}" \
           f"{'monotonic':>10}{'demo same':>10}{'left':>5}"
    lines = [head]
    for r in rows:
        lines.append(f"{r['fault']:<26}{str(r.get('survived')):>9}{str(r.get('recovery_s')):>11}"
                     f"{r.get('made', '-'):>8}{r.get('stored', '-'):>8}{r.get('lost_counted', '-'):>6}"
                     f"{r.get('unaccounted', '-'):>7}{str(r.get('versions_monotonic')):>10}"
                     f"{str(r.get('demo_identical')):>10}{r.get('left_behind', '-'):>5}")
    return "\n".join(lines)


def chaos_main(args: argparse.Namespace) -> int:
    names = [n.strip() for n in args.faults.split(",") if n.strip()]
    unknown = [n for n in names if n not in FAULTS]
    if unknown:
        print(f"laneshift chaos: unknown fault {unknown[0]!r} (known: {', '.join(FAULTS)})", file=sys.stderr)
        return 2
    work = Path(args.work_dir).resolve()
    demos = None
    if args.demos:
        from laneshift.tools.demos.generate import generate_shard

        shard = work / "demos"
        demos = str(shard) if any(shard.glob("**/metadata.json")) else \
            str(generate_shard(shard, env_id_or_scenario="lka", env_kwargs={}, episodes=6, seed=0))
    rows = []
    for name in names:
        print(f"chaos: {name} ...", file=sys.stderr, flush=True)
        rows.append(run_fault(name, work, args.env_steps, demos))
        print(f"chaos: {name}: {'survived' if rows[-1].get('survived') else 'FAILED'}, "
              f"recovery {rows[-1].get('recovery_s')} s", file=sys.stderr, flush=True)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    result = {"revision": rev, "env_steps": args.env_steps, "rows": rows}
    if args.out:  # Ray's raylet may print its own lines to stdout: a file holds the JSON alone
        Path(args.out).write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2) if args.json else render(rows))
    return 0 if all(r.get("survived") for r in rows) else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("chaos", help="the fault suite: each fault against a real 2-worker local run, one row each")
    p.add_argument("--faults", default=",".join(FAULTS), help=f"comma-separated (default: all of {', '.join(FAULTS)})")
    p.add_argument("--env-steps", type=int, default=8000, help="budget of each run (default 8000)")
    p.add_argument("--work-dir", default="runs/chaos", help="where the runs go (default runs/chaos)")
    p.add_argument("--demos", action="store_true", help="retention with a demo shard, to check its bytes stay identical")
    p.add_argument("--json", action="store_true", help="print the rows as one JSON object instead of a table")
    p.add_argument("--out", help="also write the JSON result to this file")
    p.set_defaults(func=chaos_main)
