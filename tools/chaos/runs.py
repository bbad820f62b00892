"""One run of each fault (``run_fault``), and the row that says how it went: survived, recovery
seconds, transitions made / stored / counted lost, weights versions monotonic, demo shard bytes
identical, processes left behind.

Most faults strike a real 2-worker local run (``deploy.local.train_local``) from a thread
(strikes.py); the launcher's own faults run it as a process of its own, signalled, then resumed
(``laneshift train --resume``); ``disk-full`` runs it on a small tmpfs. Processes are found through
``<run dir>/logs/<component>.pid`` (each actor writes its own).

Room: the tools (the fault suite). May import: the contract and ``deploy``.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from laneshift.config import load_run_config

from laneshift.deploy.processes import descendants, processes_holding

from .faults import FAST, FAULTS
from .strikes import FaultInjector, LinkFault, ReadOnlyRunDir, StatsFlood, checkpointing, logged_env_steps


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
        inject = StatsFlood(run_dir, at_steps=env_steps // 8, actors=spec["flood_actors"])
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
                 **({"stops": inject.stops} if getattr(inject, "when_stopped", None) else {}),
                 **({"strike_error": inject.error} if getattr(inject, "error", "") else {})}
    ended = _ended(run_dir)
    if ended is None:
        return {**row, "survived": False, "log_tail": out.getvalue()[-2000:]}
    summary, replay = ended
    made, stored, lost = _accounting(summary, replay)
    time.sleep(2)  # let Ray's processes exit before counting what is left
    row.update({"survived": rc == 0 and made == env_steps, "restarts": summary.get("restarts", {}),
                "made": made, "stored": stored, "lost_counted": lost, "unaccounted": made - stored - lost,
                "versions_monotonic": _monotonic(summary),
                "demo_identical": (_digest([demos]) == demo_before) if demos else None,
                "left_behind": len(_ray_processes(run_dir))})
    if spec.get("read_only_s"):  # the fault must have struck: writes failed, counted, and training went on
        row["write_failures_counted"] = failures = summary["write_failures"]
        row["survived"] = row["survived"] and inject.struck and sum(failures.values()) > 0
    if proxy is not None:  # every strike landed, while the run went on, and nothing was lost
        stats = proxy.stats.as_dict()
        row["link"] = {k: stats[k] for k in ("connections", "resets", "bytes_up", "bytes_down",
                                             "delay_ms_min_mean_max")}
        row["link"]["strikes"] = inject.done
        row["survived"] = row["survived"] and inject.struck
    if spec.get("flood_actors"):
        row.update(inject.report())
        # Every query answered, and all of them asked while the run was still going.
        row["survived"] = (row["survived"] and inject.struck and not summary.get("restarts")
                           and inject.stats_answered == inject.stats_asked == inject.queries
                           and inject.steps_at_end < env_steps)
    return row


def _ended(run_dir: Path) -> tuple[dict, dict] | None:
    """The run's ``summary.json`` and ``replay_stats.json``; None if either is missing or not whole."""
    try:
        return (json.loads((run_dir / "summary.json").read_text()),
                json.loads((run_dir / "replay_stats.json").read_text()))
    except (OSError, json.JSONDecodeError):
        return None


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
    ended = _ended(run_dir)
    if ended is None:
        return {**row, "survived": False, "log_tail": log.read_text()[-2000:]}
    summary, replay = ended
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
        try:
            summary = json.loads((run_dir / "summary.json").read_text())
            replay = json.loads((run_dir / "replay_stats.json").read_text())
        except (OSError, ValueError) as exc:  # the run's end records did not land: the row says so
            return {"fault": name, "rc": rc, "wall_s": round(time.monotonic() - started, 1), "injected": True,
                    "survived": False, "why": f"the run's end records are missing: {exc}",
                    "log_tail": out.getvalue()[-3000:]}
        made = sum(w["env_steps"] for w in summary["workers"])
        stored, lost = int(replay["tables"]["online"]["inserted"]), int(summary["replay"]["lost_items"])
        failures = summary["write_failures"]
        time.sleep(2)
        return {"fault": name, "rc": rc, "wall_s": round(time.monotonic() - started, 1), "injected": True,
                "recovery_s": 0.0, "survived": rc == 0 and made == env_steps and sum(failures.values()) > 0,
                "made": made, "stored": stored, "lost_counted": lost, "unaccounted": made - stored - lost,
                "versions_monotonic": True, "demo_identical": None, "left_behind": len(_ray_processes(run_dir)),
                "write_failures_counted": failures, "restarts": summary.get("restarts", {})}
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


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
    return processes_holding(str(run_dir))
