"""``laneshift bench run``: a whole local run measured from outside: start-up, throughput, memory.

What it is: the launcher started as its own process (``laneshift train --local ...``, the
arguments of ``make train`` unless told otherwise), watched every 0.5 s through /proc:

* start-up: seconds from the command until its progress line first shows an env step stored;
* throughput: env steps/s and learner updates/s over the run, from its summary;
* memory: the process tree's RSS and PSS summed at each sample (peak over the run), and each
  process's own peak, named by what it is (launcher, each component, Ray's own processes).
  PSS splits shared pages between the processes that share them, so the PSS sum is what the run
  really costs; the RSS sum counts shared libraries (torch) once per process.

Why /proc and not psutil: psutil is not a dependency, and two files per process say it all.
Room: the tools (benchmarks). May import: the contract and ``deploy`` (its process-tree reader); the run
itself is a ``laneshift train`` subprocess.

    laneshift bench run --json
    laneshift bench run --train-args "--workers 4 --env-steps 40000"
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable

from laneshift.deploy.processes import descendants

#: ``make train``'s run without its demo phase: what a user's first run costs.
DEFAULT_TRAIN_ARGS = "--workers 2 --scenario straight --env-steps 20000"
_STEPS = re.compile(r"steps\s+([\d,]+)/")


def _read_kb(path: str, field: str) -> int:
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(field):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return 0


#: Processes named by a part of their command line (Ray titles an actor's process ray::Class).
LANESHIFT_ACTORS = (("ray::RouterActor", "router"), ("ray::ReplayServerActor", "replay-server"),
                    ("ray::LearnerActor", "learner"), ("ray::EnvWorkerActor", "env-worker"))
_RAY_PROCESSES = (("gcs_server", "ray gcs"), ("raylet", "ray raylet"), ("dashboard/agent.py", "ray dashboard agent"),
                  ("runtime_env/agent", "ray runtime-env agent"), ("log_monitor.py", "ray log monitor"),
                  ("monitor.py", "ray monitor"), ("dashboard.py", "ray dashboard"),
                  ("default_worker.py", "ray-worker (idle)"))


def process_label(pid: int, root: int, root_label: str = "launcher",
                  actors: tuple[tuple[str, str], ...] = LANESHIFT_ACTORS) -> str:
    """What a process of the tree is, from its command line: ``root_label`` for the root, an actor
    by ``actors`` (part of the command line, label), else Ray's own processes by their files."""
    if pid == root:
        return root_label
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return "?"
    for part, label in actors:
        if part in cmd:
            return label
    if cmd.startswith("ray::"):
        return "ray-worker (" + cmd.split()[0][5:] + ")"
    for part, label in _RAY_PROCESSES:
        if part in cmd:
            return label
    if "laneshift.deploy.spec_process" in cmd:
        return "env spec (the launcher's child, during Ray's start)"
    if "laneshift-ray-reaper" in cmd:
        return "temp-dir watcher"  # the launcher's: removes Ray's temp dir if the launcher is killed
    return Path(cmd.split()[0]).name if cmd.strip() else "?"


class TreeSampler(threading.Thread):
    """Samples the RSS and PSS of ``root`` and everything below it until stopped; ``label(pid,
    root)`` names each process (``process_label`` by default)."""

    def __init__(self, root: int, period_s: float = 0.5, label: Callable[[int, int], str] = process_label):
        super().__init__(daemon=True, name="tree-sampler")
        self.root, self.period_s, self.label = root, period_s, label
        self.peak_rss_kb = self.peak_pss_kb = self.max_processes = 0
        self.per_process: dict[int, dict] = {}  # pid -> {"label", "rss_kb", "pss_kb"} (peaks)
        self._halt = threading.Event()

    def sample(self) -> None:
        rss = pss = n = 0
        for pid in {self.root} | descendants(self.root):
            r = _read_kb(f"/proc/{pid}/status", "VmRSS:")
            if not r:
                continue
            p = _read_kb(f"/proc/{pid}/smaps_rollup", "Pss:")
            rss, pss, n = rss + r, pss + p, n + 1
            seen = self.per_process.setdefault(pid, {"label": "?", "rss_kb": 0, "pss_kb": 0})
            # Again each time: a Ray worker is "default_worker.py" until it becomes an actor. An
            # ending process (a zombie has no command line) keeps the name it had.
            label = self.label(pid, self.root)
            if label != "?" or seen["label"] == "?":
                seen["label"] = label
            seen["rss_kb"], seen["pss_kb"] = max(seen["rss_kb"], r), max(seen["pss_kb"], p)
        self.peak_rss_kb, self.peak_pss_kb = max(self.peak_rss_kb, rss), max(self.peak_pss_kb, pss)
        self.max_processes = max(self.max_processes, n)

    def run(self) -> None:
        while not self._halt.wait(self.period_s):
            self.sample()

    def stop(self) -> None:
        self._halt.set()
        self.join(5)

    def by_label(self) -> dict[str, dict]:
        """Each kind of process: how many, and the largest one's peak RSS / PSS in MB."""
        out: dict[str, dict] = {}
        for p in self.per_process.values():
            row = out.setdefault(p["label"], {"count": 0, "rss_mb": 0.0, "pss_mb": 0.0})
            row["count"] += 1
            row["rss_mb"] = max(row["rss_mb"], round(p["rss_kb"] / 1024, 1))
            row["pss_mb"] = max(row["pss_mb"], round(p["pss_kb"] / 1024, 1))
        return dict(sorted(out.items(), key=lambda kv: -kv[1]["pss_mb"]))


_API = re.compile(r"replay inspection API (http://\S+)/stats")


class FirstInsert(threading.Thread):
    """Polls the replay server's HTTP /stats every 0.1 s until it holds a transition; records when."""

    def __init__(self, url: str, started: float):
        super().__init__(daemon=True, name="first-insert")
        self.url, self.started, self.seconds = url, started, None
        self.start()

    def run(self) -> None:
        import urllib.request

        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(self.url + "/stats", timeout=2) as reply:
                    if json.loads(reply.read())["tables"]["online"]["inserted"] > 0:
                        self.seconds = round(time.monotonic() - self.started, 2)
                        return
            except (OSError, ValueError, KeyError):
                pass
            time.sleep(0.1)


def bench_run(train_args: str, timeout_s: float = 900.0) -> dict:
    if any(arg.split("=")[0] == "--run-dir" for arg in shlex.split(train_args)):
        # argparse keeps the last --run-dir: the run would go there and its result be lost.
        raise SystemExit("bench run: --train-args must not hold --run-dir (each run gets a fresh one of its own)")
    run_dir = Path(tempfile.mkdtemp(prefix="lsbench-")) / "run"
    cmd = [sys.executable, "-m", "laneshift", "train", "--local", "--run-dir", str(run_dir), *shlex.split(train_args)]
    started = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    sampler = TreeSampler(proc.pid)
    sampler.start()
    first_step_s, tail, first_insert, started_line = None, [], None, ""
    try:
        for line in proc.stdout:
            tail = (tail + [line])[-40:]
            api = _API.search(line)
            if api and first_insert is None:
                first_insert = FirstInsert(api.group(1), started)
            if line.startswith("train: started in"):
                started_line = line.strip()
            m = _STEPS.search(line)
            if first_step_s is None and m and int(m.group(1).replace(",", "")) > 0:
                first_step_s = round(time.monotonic() - started, 1)
            if time.monotonic() - started > timeout_s:
                proc.kill()
                break
        rc = proc.wait(60)
    finally:
        sampler.stop()
        if proc.poll() is None:
            proc.kill()
    wall = round(time.monotonic() - started, 1)
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, json.JSONDecodeError):
        return {"rc": rc, "error": "no summary.json", "log_tail": "".join(tail)}
    learner = summary.get("learner", {})
    return {
        "train_args": train_args, "rc": rc, "wall_s": wall,
        # From the command to the first transition the replay server stored (its HTTP /stats polled
        # every 0.1 s), and to the first progress line that counts env steps (the learner counts
        # them from finished episodes, so this is later by about one episode and one log interval).
        "first_stored_s": first_insert.seconds if first_insert else None, "first_progress_s": first_step_s,
        "startup_line": started_line,
        "env_steps": summary["env_steps"], "run_s": summary["wall_s"],
        "env_steps_per_s": round(summary["env_steps"] / max(summary["wall_s"], 1e-6), 1),
        "updates": learner.get("updates"), "updates_per_s": learner.get("updates_per_s"),
        **training_rate(run_dir),
        **summary.get("waits", {}),  # which side bounded the run (deploy.summary.wait_shares)
        "peak_tree_rss_mb": round(sampler.peak_rss_kb / 1024), "peak_tree_pss_mb": round(sampler.peak_pss_kb / 1024),
        "processes": sampler.by_label(), "run_dir": str(run_dir),
    }


def training_rate(run_dir: Path) -> dict:
    """Env steps/s and updates/s while training: from the learner's first record that counts env
    steps to its last (``metrics.jsonl``), so Ray's start and the final stop are left out."""
    recs = []
    try:
        for line in (run_dir / "metrics.jsonl").read_text().splitlines():
            rec = json.loads(line)
            if rec.get("kind") == "learner" and rec.get("env_steps", 0) > 0:
                recs.append((float(rec["time"]), int(rec["env_steps"]), int(rec.get("updates", 0))))
    except (OSError, ValueError):
        return {}
    if len(recs) < 2 or recs[-1][0] <= recs[0][0]:
        return {}
    span = recs[-1][0] - recs[0][0]
    out = {"training_s": round(span, 1), "training_env_steps_per_s": round((recs[-1][1] - recs[0][1]) / span, 1),
           "training_updates_per_s": round((recs[-1][2] - recs[0][2]) / span, 1)}
    # The steady state: the last two thirds of training, past the ramp (replay filling to
    # min_size, the first weights reaching the workers, the rate limiter finding its pace).
    third = next(r for r in recs if r[0] >= recs[0][0] + span / 3)
    if recs[-1][0] > third[0]:
        steady = recs[-1][0] - third[0]
        out.update({"steady_s": round(steady, 1),
                    "steady_env_steps_per_s": round((recs[-1][1] - third[1]) / steady, 1),
                    "steady_updates_per_s": round((recs[-1][2] - third[2]) / steady, 1)})
    return out


def render(r: dict) -> str:
    if "error" in r:
        return f"bench run: {r['error']} (rc {r['rc']})\n{r.get('log_tail', '')}"
    lines = [f"laneshift train --local {r['train_args']}",
             f"  first transition stored {r['first_stored_s']} s after the command ({r['startup_line']}); run {r['run_s']} s, "
             f"{r['env_steps_per_s']} env steps/s overall; while training {r.get('training_env_steps_per_s')} env steps/s, "
             f"{r.get('training_updates_per_s')} updates/s ({r['updates']} updates); last two thirds of training "
             f"{r.get('steady_env_steps_per_s')} env steps/s, {r.get('steady_updates_per_s')} updates/s",
             f"  peak process tree: RSS {r['peak_tree_rss_mb']} MB, PSS {r['peak_tree_pss_mb']} MB",
             f"  {'process':<28}{'count':>6}{'peak RSS MB':>13}{'peak PSS MB':>13}"]
    for label, p in r["processes"].items():
        lines.append(f"  {label:<28}{p['count']:>6}{p['rss_mb']:>13}{p['pss_mb']:>13}")
    return "\n".join(lines)


def bench_run_main(args: argparse.Namespace) -> int:
    result = bench_run(args.train_args)
    print(json.dumps(result, indent=2) if args.json else render(result))
    return 0 if result.get("rc") == 0 else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="a whole local run measured from outside: start-up, env steps/s, memory per process",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--train-args", default=DEFAULT_TRAIN_ARGS, help="arguments for `laneshift train --local`")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=bench_run_main)
