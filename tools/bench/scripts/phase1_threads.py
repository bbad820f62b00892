"""Phase 1's update rate with the learner pinned to one CPU against phase 1 on every CPU
(``learner.phase1_threads`` 1 against 0): whole ``laneshift train`` runs in local mode, alternating
A B A B, each network width its own pair. The rate is read from the run's ``metrics.jsonl``: the
updates between the first and the last phase-1 record over the time between them.

    python tools/bench/scripts/phase1_threads.py --rounds 2 --hidden 256,256 512,512
    python tools/bench/scripts/phase1_threads.py --threads 0 --laneshift OTHER_CHECKOUT/.venv/bin/laneshift
    python tools/bench/scripts/phase1_threads.py --hidden 512,512 --set learner.mlp_precision=bf16
    python tools/bench/scripts/phase1_threads.py --threads 1,2,0 --busy 1 --updates 2000 --hidden 256,256

``--busy N``: N processes that keep a CPU busy each (a bare Python loop) beside every timed run, as a
test suite or another job beside a training run does; phase1_threads 0 times one thread per CPU
against one as it goes (``learner.cpus.ThreadChooser``), 2 is two threads whatever happens.

Needs a quiet machine otherwise (a training run beside it measures the other run). The demo shard
is made by the first (untimed) run and reused.

Room: the tools (benchmark scripts). May import: the standard library; runs ``laneshift`` as a
command.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path


def phase1_rate(metrics: Path) -> float:
    """Updates per second over the phase-1 records of a run's metrics.jsonl."""
    recs = [r for r in map(json.loads, metrics.read_text().splitlines())
            if r.get("kind") == "learner" and r.get("phase") == 1]
    if len(recs) < 2 or recs[-1]["time"] <= recs[0]["time"]:
        raise SystemExit(f"phase1_threads: fewer than two phase-1 records in {metrics}")
    return (recs[-1]["updates"] - recs[0]["updates"]) / (recs[-1]["time"] - recs[0]["time"])


def train(run_dir: Path, args: argparse.Namespace, hidden: str, threads: int, updates: int | None = None) -> float:
    """One run; its phase-1 rate, or 0.0 for a warm-up (``updates`` given: too short to rate)."""
    cmd = [args.laneshift, "train", "--scenario", args.scenario, "--method", args.method,
           "--env-steps", str(args.env_steps), "--run-dir", str(run_dir), "--overwrite",
           "--set", f"learner.phase1_updates={updates or args.updates}", "--set", f"learner.hidden={hidden}",
           "--set", f"learner.phase1_threads={threads}", "--set", "train.eval_episodes=0"]
    for extra in args.set:
        cmd += ["--set", extra]
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(0 if updates else args.busy)]
    try:
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    finally:
        for proc in busy:  # ours, by PID
            proc.kill()
            proc.wait()
    return 0.0 if updates else phase1_rate(run_dir / "metrics.jsonl")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--hidden", nargs="+", default=["256,256", "512,512"], help="learner.hidden values")
    p.add_argument("--updates", type=int, default=5000, help="learner.phase1_updates per run")
    p.add_argument("--env-steps", type=int, default=2000)
    p.add_argument("--scenario", default="merge")
    p.add_argument("--method", default="dqfd-bc-alongside-gaps-safe-shield")
    p.add_argument("--threads", default="1,0", help="learner.phase1_threads values, alternated (default 1,0)")
    p.add_argument("--busy", type=int, default=0, metavar="N",
                   help="N busy processes (one CPU each) beside every timed run (default 0: a quiet machine)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a config value for every run (repeatable), e.g. learner.mlp_precision=bf16")
    p.add_argument("--laneshift", default=str(Path(sys.executable).with_name("laneshift")),
                   help="the laneshift command (another checkout's, to compare two revisions)")
    args = p.parse_args(argv)
    settings = [int(t) for t in args.threads.split(",")]
    with tempfile.TemporaryDirectory(prefix="phase1-threads-") as tmp:
        train(Path(tmp) / "warmup", args, args.hidden[0], settings[0], updates=200)  # the demo shard; not timed
        rates: dict[tuple[str, int], list[float]] = {}
        for r in range(args.rounds):
            for hidden in args.hidden:
                for threads in settings:  # A B: drift hits both alike
                    rate = train(Path(tmp) / f"r{r}-{hidden}-{threads}", args, hidden, threads)
                    rates.setdefault((hidden, threads), []).append(rate)
                    print(f"round {r} hidden {hidden} phase1_threads {threads}: {rate:.1f} updates/s", flush=True)
    for hidden in args.hidden:
        means = {t: statistics.fmean(rates[hidden, t]) for t in settings}
        line = ", ".join(f"phase1_threads {t}: {m:.1f} updates/s" for t, m in means.items())
        if 1 in means and 0 in means:
            line += f" (every CPU against pinned: {means[0] / means[1]:.2f}x)"
        print(f"hidden {hidden}{f', {args.busy} busy process(es) beside' if args.busy else ''}: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
