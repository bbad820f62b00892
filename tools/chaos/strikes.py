"""The faults' strikes: threads that watch a running training run and strike it once it has made
so many env steps (``metrics.jsonl``), then measure its recovery: the seconds until its env steps
and learner updates move again.

- ``FaultInjector``: a signal to one component's process (its ``<run dir>/logs/<component>.pid``);
- ``LinkFault``: connection resets and a cut on the workers' link, through a ``linkproxy``;
- ``ReadOnlyRunDir``: the run dir read-only for a while (a bind mount remounted ro; root);
- ``StatsFlood``: thousands of foreign actor names and stats queries through the router.

Each is a ``Strike``: a daemon thread with a deadline, a ``stop()`` that ends its waiting at once
and the recovery seconds it measured (``recovery_s``, None when the run did not recover).

Room: the tools (the fault suite). May import: the contract, ``laneshift.actors.envs`` (a stats
flood's observation shape), ``laneshift.replay_server.wal`` (what the replay server's log holds)
and the standard library.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar

from laneshift.config import load_run_config
from laneshift.replay_server import wal as wal_log


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
    """True while the replay server is writing a checkpoint (its temp dir exists until the rename)
    and its write-ahead log holds a batch after the last whole checkpoint's cut: the batches a kill
    in the middle of the copy puts to the test. (Without one the restart has nothing to replay; CI
    met that: the workers were held by the replay ratio, and the kill landed in the cut, between
    the removal of the empty segment before it and the creation of the next.)"""
    unfinished = run_dir / "replay_checkpoint.tmp"
    return lambda: unfinished.is_dir() and _logged_after_cut(run_dir / "replay_checkpoint")


def _logged_after_cut(checkpoint_dir: Path) -> bool:
    """Whether a segment of the log from the checkpoint's ``wal_from`` on holds a batch."""
    try:
        wal_from = int(json.loads((checkpoint_dir / "meta.json").read_text()).get("wal_from") or 0)
    except (OSError, ValueError):  # between the two renames that put a checkpoint in place
        return False
    for gen, path in wal_log.segments(wal_log.directory_for(checkpoint_dir)):
        try:
            records = wal_log.scan(path.read_bytes())[0] if gen >= wal_from else []
        except OSError:  # deleted as it was read
            continue
        if any(kind == wal_log.TRANSITIONS for kind, _, _ in records):
            return True
    return False


def _reached(run_dir: Path, steps: int) -> Callable[[], bool]:
    return lambda: logged_env_steps(run_dir)[0] >= steps


@dataclass(eq=False)  # a Thread must stay hashable
class Strike(threading.Thread):
    """A strike's thread (named ``inject-<what>``): ``run()`` waits for its moment, strikes, and sets
    ``recovery_s``; ``stop()`` ends any wait at once."""

    WHAT: ClassVar[str] = ""

    run_dir: Path
    timeout_s: float = field(default=300.0, kw_only=True)
    recovery_s: float | None = field(default=None, kw_only=True)
    _halt: threading.Event = field(default_factory=threading.Event, kw_only=True)

    def __post_init__(self) -> None:
        threading.Thread.__init__(self, daemon=True, name=f"inject-{self.what()}")

    def what(self) -> str:
        return self.WHAT

    def _reach(self, steps: int, deadline: float) -> bool:
        """Wait until the run made ``steps`` env steps (False: the deadline passed or stop())."""
        return _wait_until(_reached(self.run_dir, steps), deadline, self._halt)

    def _recover(self, before: tuple[int, int], since: float, deadline: float) -> None:
        self.recovery_s = _recovery_s(self.run_dir, before, since, deadline, self._halt)

    def stop(self) -> None:
        self._halt.set()


@dataclass(eq=False)
class FaultInjector(Strike):
    """Sends ``sig`` to ``component``'s process once the run has made ``at_steps`` env steps and
    ``ready()`` holds; then measures recovery: seconds until env steps (and updates) move again."""

    component: str
    at_steps: int
    ready: Callable[[], bool] = lambda: True
    # If set: once ready, the process is stopped (SIGSTOP) and this is checked while it cannot
    # move; the signal is sent only if it holds (else SIGCONT, and again 50 ms later). For a state
    # that lasts a moment, such as a checkpoint being written.
    when_stopped: Callable[[], bool] | None = None
    stops: int = 0  # SIGSTOPs sent for when_stopped
    sig: int = signal.SIGKILL
    killed_pid: int | None = None
    killed_at: float | None = None

    def what(self) -> str:
        return self.component

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
        self._recover(before, self.killed_at, deadline)

    @property
    def struck(self) -> bool:
        return self.killed_pid is not None


@dataclass(eq=False)
class LinkFault(Strike):
    """Strikes the workers' link through ``proxy`` once the run has made each of ``resets_at`` env
    steps (every live connection reset) and ``hold_at`` (a cut of ``hold_s``: nothing moves, no
    connection closes); recovery is measured from the last strike (from the end of a cut)."""

    WHAT = "link"

    proxy: Any
    resets_at: list[int]
    hold_at: int | None = None
    hold_s: float = 0.0
    done: list[str] = field(default_factory=list)

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
        self._recover(before, since, deadline)

    @property
    def struck(self) -> bool:
        return len(self.done) == len(self.resets_at) + (self.hold_at is not None)


@dataclass(eq=False)
class ReadOnlyRunDir(Strike):
    """Makes the run dir read-only once the run made ``at_steps`` env steps, until ``until_steps``
    (at most ``seconds``): a bind mount of it onto itself, remounted ro (EROFS even for root; files
    already open keep writing, as on a filesystem remounted read-only under a running job), then
    unmounted, so the run ends on a writable dir and its summary shows what was counted."""

    WHAT = "read-only"

    at_steps: int
    until_steps: int  # writable again once the run made this many env steps, or after ``seconds``
    seconds: float
    struck: bool = False
    error: str = ""

    def run(self) -> None:
        deadline = time.monotonic() + self.timeout_s
        if not self._reach(self.at_steps, deadline):
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
            self._reach(self.until_steps, time.monotonic() + self.seconds)
        finally:
            subprocess.run(["umount", "-l", where], check=False)
        before, back = logged_env_steps(self.run_dir), time.monotonic()
        self._recover(before, back, deadline)


@dataclass(eq=False)
class StatsFlood(Strike):
    """A foreign zenoh client, once the run made ``at_steps`` env steps: one one-row batch under each
    of ``actors`` names (more than the replay server keeps state for), with a stats query after each
    tenth of them. The learner, the launcher and every stats reply must come through it.

    The queries go out during the flood, not after it: asked after it (10 queries 0.2 s apart, 2 s
    in all), the last ones could come after an idle machine's short run had ended, and a reply
    missing for that reason says nothing of the server."""

    WHAT = "stats-flood"

    at_steps: int
    actors: int
    queries: int = 10
    struck: bool = False
    stats_asked: int = 0
    stats_answered: int = 0
    largest_reply: int = 0
    steps_at_end: int = 0
    unanswered: list[dict] = field(default_factory=list)

    def run(self) -> None:
        import numpy as np

        from laneshift import transport, wire
        from laneshift.actors.envs import spec_of

        deadline = time.monotonic() + self.timeout_s
        if not self._reach(self.at_steps, deadline):
            return
        cfg = load_run_config(self.run_dir / "config.yaml")  # as the launcher resolved it: the router's endpoint
        schema = spec_of(cfg.env).schema
        obs = np.zeros((1, *schema.obs_shape), schema.obs_dtype)
        before, began = logged_env_steps(self.run_dir), time.monotonic()
        ask_every = max(1, self.actors // self.queries)
        with transport.open_session(cfg.transport, "client", cfg.max_message_bytes) as session:
            for i in range(self.actors):
                name = f"flood{i:05d}"
                batch = wire.TransitionBatch.from_arrays(
                    actor=name, seq=0, weights_version=0, phase=0, env_steps=1, obs=obs, action=np.zeros(1),
                    reward=np.zeros(1), next_obs=obs, terminated=np.zeros(1), truncated=np.zeros(1))
                session.put(wire.transitions_key(cfg.transport.run_id, name), wire.encode_transitions(batch),
                            congestion_control=transport.zenoh.CongestionControl.BLOCK)
                if (i + 1) % ask_every == 0 and self.stats_asked < self.queries:
                    self._ask(session, cfg.transport.run_id, began)
            self.struck = True
        self.steps_at_end = logged_env_steps(self.run_dir)[0]
        self._recover(before, began, deadline)

    def _ask(self, session, run_id: str, began: float) -> None:
        from laneshift import transport, wire

        self.stats_asked += 1
        asked = time.monotonic()
        reply = transport.query_ok(session, wire.replay_stats_key(run_id), b"{}", 10.0)
        if isinstance(reply, (bytes, bytearray)):
            self.stats_answered += 1
            self.largest_reply = max(self.largest_reply, len(reply))
        else:  # when it was asked, what came back, and whether the run was still going
            self.unanswered.append({"asked_s": round(asked - began, 2), "waited_s": round(time.monotonic() - asked, 2),
                                    "reply": "none" if reply is None else str(reply)[:200],
                                    "env_steps_logged": logged_env_steps(self.run_dir)[0],
                                    "run_ended": (self.run_dir / "summary.json").exists()})

    def report(self) -> dict:
        return {"flood_actors": self.actors, "stats_answered": f"{self.stats_answered}/{self.stats_asked}",
                "largest_stats_reply_bytes": self.largest_reply, "env_steps_after_flood": self.steps_at_end,
                **({"stats_unanswered": self.unanswered} if self.unanswered else {})}
