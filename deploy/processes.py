"""Child processes of a local run: started with logs in the run dir, always reaped.

    >>> group = ProcessGroup(Path("runs/x/logs"))  # doctest: +SKIP
    >>> group.start("router", [sys.executable, "-m", "laneshift", "router", "--listen", ep])  # doctest: +SKIP
    >>> group.stop_all()  # SIGTERM, then SIGKILL after a grace period  # doctest: +SKIP

Room: deploy, the wiring. May import: the contract, the components and the demo tools; never the
studies, the benchmarks or the CLI.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path


class ChildFailed(RuntimeError):
    pass


def terminate(proc: subprocess.Popen, grace_s: float, kill_wait_s: float = 10.0) -> int | None:
    """SIGTERM ``proc`` (by its PID), SIGKILL if it is still there after ``grace_s``; its exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(kill_wait_s)
    return proc.returncode


class ProcessGroup:
    def __init__(self, log_dir: Path):
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, subprocess.Popen] = {}
        self.argv: dict[str, list[str]] = {}
        self.restarts: dict[str, int] = {}

    def start(self, name: str, argv: list[str]) -> subprocess.Popen:
        log = (self.log_dir / f"{name}.log").open("ab")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env)
        log.close()
        self.procs[name] = proc
        self.argv[name] = list(argv)
        return proc

    def restart_if_dead(self, name: str, max_restarts: int) -> bool:
        """Start ``name`` again with the same command if it exited; False once out of restarts."""
        proc = self.procs[name]
        if proc.poll() is None:
            return True
        if self.restarts.get(name, 0) >= max_restarts:
            return False
        self.restarts[name] = self.restarts.get(name, 0) + 1
        self.start(name, self.argv[name])
        return True

    def log_tail(self, name: str, lines: int = 15) -> str:
        path = self.log_dir / f"{name}.log"
        try:
            return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def check_alive(self, names: list[str] | None = None) -> None:
        """Raise ChildFailed (with the end of its log) if a child exited."""
        for name, proc in self.procs.items():
            if (names is None or name in names) and proc.poll() is not None:
                raise ChildFailed(f"{name} exited with code {proc.returncode}; end of {self.log_dir / name}.log:\n"
                                  f"{self.log_tail(name)}")

    def wait(self, name: str, timeout: float) -> int | None:
        try:
            return self.procs[name].wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def stop(self, name: str, grace_s: float = 10.0) -> None:
        proc = self.procs.get(name)
        if proc is not None:
            terminate(proc, grace_s, kill_wait_s=5)

    def stop_all(self, grace_s: float = 10.0) -> None:
        # Reverse start order: learner, then replay server, then the router they talk through.
        for name in reversed(list(self.procs)):
            self.stop(name, grace_s)


def wait_for_file(path: Path, timeout_s: float, group: ProcessGroup, name: str) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.exists():
            return
        group.check_alive([name])
        time.sleep(0.05)
    raise ChildFailed(f"{name} did not become ready in {timeout_s:.0f} s; end of its log:\n{group.log_tail(name)}")


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` now (children, their children, ...), read from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def processes_holding(d: str) -> list[int]:
    """The other processes that hold a file open under the directory ``d``. Standard library
    alone: its source is also the private Ray temp dir reaper's (``ray_connection._temp_dir_reaper``)."""
    left = []
    for q in os.listdir("/proc"):
        if not q.isdigit() or int(q) == os.getpid():
            continue
        try:
            fds = [os.readlink(f"/proc/{q}/fd/{f}") for f in os.listdir(f"/proc/{q}/fd")]
        except OSError:
            continue
        if any(f.startswith(d + "/") for f in fds):
            left.append(int(q))
    return left


def end_processes_holding(d: str, tries: int = 20) -> None:
    """SIGKILL every other process that holds a file open under ``d`` (the launcher's private Ray
    temp dir: only Ray's processes of its own cluster), until none does; as ``processes_holding``,
    the reaper runs its source."""
    for _ in range(tries):
        left = processes_holding(d)
        if not left:
            return
        for q in left:
            try:
                os.kill(q, signal.SIGKILL)
            except OSError:
                pass
        time.sleep(0.5)
