"""The pixel study on one GPU: three seeds side by side, each in in-process mode (its env workers
and its learner as threads of one process, ``deploy.inprocess.train_inprocess``), the learner on
cuda, every run ended by a wall-clock deadline; then each seed's final network is tested here on
the CPU (``test.sh`` beside this file) on the protocol's test episodes.

    python run_gpu.py --out OUT --seconds 420 --env-steps 80000 [--seeds 0,1,2] [--device cuda] [--set K=V]

What it writes in OUT: ``seed<N>.safetensors`` (the final network of each seed), ``results.json``
(per seed: env steps, updates, wall seconds, the learner's last status, the device's name) and
``train.log`` (the seeds' logs, one after the other). The recipe is ``RECIPE`` below: the CPU probe's
(``../pixels-probe-150k/run.sh``: dqfd-bc-anneal, SmallCNN, bf16 convolutions, DrQ's shift, step size
1e-4 -> 1e-5) with four times the sampled rows per env step, which the GPU learner can afford.

Why a process per seed: the workers and the learner of one run share a GIL; three processes use
three of the machine's cores and the one GPU. Why a deadline: a device call is limited in time; a
run stopped early still writes its final network (the schedules then stop short of their ends,
which ``results.json`` shows as env steps below ``--env-steps``).

Room: a study script (docs/results). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

# The GPU recipe: the CPU probe's settings, batch 128 and 32 sampled rows per env step (the probe: 32
# and 8), 8,000 pre-training updates of 128 (the probe: 20,000 of 32), three workers per seed.
RECIPE = {
    "env.scenario": "straight", "env.observation": "grayscale",
    "learner.cnn": "small", "learner.cnn_precision": "bf16", "learner.augment": "shift",
    "learner.batch_size": 128, "replay.samples_per_insert": 32, "replay.capacity": 200_000,
    "learner.lr": 1e-4, "learner.lr_final": 1e-5, "learner.phase1_updates": 8000,
    "actor.workers": 3, "train.eval_episodes": 0,
}
METHOD = "dqfd-bc-anneal"


def seed_config(args: argparse.Namespace, run_dir: Path, extra: dict[str, str] | None = None):
    """Seed ``args.one``'s config: the method, the recipe, ``--set`` (and ``extra``) over it; the
    scripted pixel shard found (or made) under ``<runs>/demos``."""
    from laneshift.config import load_run_config, method_settings
    from laneshift.deploy.run_dir import ensure_demo_shard
    from laneshift.tools.argtypes import parse_set

    seed = args.one
    cfg = load_run_config(overrides={
        **method_settings(METHOD, "--method"), **RECIPE, **parse_set(args.set), **(extra or {}),
        "learner.device": args.device, "train.run_dir": str(run_dir), "train.env_steps": args.env_steps,
        "train.seed": seed, "actor.seed": seed, "learner.seed": seed, "replay.seed": seed,
        "transport.run_id": f"{METHOD}-s{seed}"})
    return ensure_demo_shard(cfg, sys.stdout)


def write_summary(args: argparse.Namespace, run_dir: Path, summary: dict) -> int:
    """``<run dir>/summary.json`` with the device and torch beside ``summary``; its head on stdout."""
    import torch

    summary = {"seed": args.one, **summary, "torch": torch.__version__,
               "device": torch.cuda.get_device_name(0) if args.device == "cuda" else "cpu"}
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    print(json.dumps({k: summary[k] for k in ("seed", "wall_s", "env_steps", "updates", "device")}), flush=True)
    return 0


def one_seed(args: argparse.Namespace) -> int:
    """One seed's run in this process; its summary as JSON in ``<run dir>/summary.json``."""
    from laneshift.deploy.inprocess import train_inprocess

    run_dir = Path(args.runs) / f"seed{args.one}"
    cfg = seed_config(args, run_dir)
    stop = threading.Event()
    deadline = threading.Timer(args.seconds, stop.set)
    deadline.start()
    started = time.perf_counter()
    result = train_inprocess(cfg, stop)
    wall = time.perf_counter() - started
    deadline.cancel()
    return write_summary(args, run_dir, {
        "wall_s": round(wall, 1), "stopped_by_deadline": stop.is_set(),
        "env_steps": sum(w["env_steps"] for w in result["workers"]), "updates": result["updates"],
        "learner": result["learner"], "replay_inserted": result["replay"]["tables"]["online"]["inserted"]})


def one_seed_processes(args: argparse.Namespace) -> int:
    """One seed's run as separate processes, no Ray: ``laneshift replay-server`` (the zenoh router
    too), ``laneshift learner`` and ``actor.workers`` x ``laneshift worker``; at the deadline the
    workers get SIGTERM (each sends its last batch), then the learner (its final checkpoint), then
    the replay server. Its summary in ``<run dir>/summary.json``."""
    from laneshift import transport
    from laneshift.config import save_run_config
    from laneshift.deploy.processes import ProcessGroup, terminate, wait_for_file

    run_dir = Path(args.runs) / f"seed{args.one}"
    cfg = seed_config(args, run_dir, {"transport.router": f"tcp/127.0.0.1:{transport.free_tcp_port()}"})
    config = save_run_config(cfg, run_dir / "config.yaml")
    group = ProcessGroup(run_dir / "logs")
    laneshift = [sys.executable, "-m", "laneshift"]
    started = time.perf_counter()
    try:
        group.start("replay-server", [*laneshift, "replay-server", "--config", str(config), "--embedded-router",
                                      "--ready-file", str(run_dir / "ready")])
        wait_for_file(run_dir / "ready", 300, group, "replay-server")
        group.start("learner", [*laneshift, "learner", "--config", str(config)])
        workers = [f"w{i}" for i in range(cfg.actor.workers)]
        for i, name in enumerate(workers):
            group.start(name, [*laneshift, "worker", "--config", str(config), "--index", str(i)])
        deadline = started + args.seconds
        while time.perf_counter() < deadline and any(group.procs[n].poll() is None for n in workers):
            time.sleep(1.0)
        stopped_by_deadline = any(group.procs[n].poll() is None for n in workers)
        for name in workers:
            terminate(group.procs[name], grace_s=30)
        wall = time.perf_counter() - started
        group.stop("learner", grace_s=60)
        # The study keeps no replay state: a replay server still writing its final checkpoint of
        # pixel items after 5 s is not waited for.
        group.stop("replay-server", grace_s=5)
    finally:
        group.stop_all()
    summaries = []
    for name in workers:
        lines = [ln for ln in (run_dir / "logs" / f"{name}.log").read_text().splitlines() if ln.startswith("{")]
        summaries.append(json.loads(lines[-1]) if lines else {"name": name, "env_steps": 0, "missing": True})
    records = [json.loads(ln) for ln in (run_dir / "metrics.jsonl").read_text().splitlines() if ln.startswith("{")]
    last = next((r for r in reversed(records) if "updates" in r), {})
    return write_summary(args, run_dir, {
        "mode": "processes", "wall_s": round(wall, 1), "stopped_by_deadline": stopped_by_deadline,
        "env_steps": sum(w.get("env_steps", 0) for w in summaries), "updates": last.get("updates"),
        "learner": last, "workers": summaries})


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="folder for the networks, results.json and train.log")
    p.add_argument("--runs", default=str(Path(__file__).resolve().parents[3] / ".gpu" / "runs"),
                   help="run dirs (and the demo shard under demos/): default <repo>/.gpu/runs")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--seconds", type=float, required=True, help="each run's wall-clock deadline")
    p.add_argument("--env-steps", type=int, required=True, help="each run's budget (the schedules' length)")
    p.add_argument("--device", default="cuda", choices=("cuda", "cpu"))
    p.add_argument("--mode", default="inprocess", choices=("inprocess", "processes"),
                   help="inprocess: each seed one process of threads; processes: each seed a replay server, "
                        "a learner and its workers as processes of their own (no Ray)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a config field over the recipe (a smoke test's smaller pre-training, say)")
    p.add_argument("--one", type=int, help=argparse.SUPPRESS)  # a seed's own process
    args = p.parse_args()
    if args.one is not None:
        return one_seed_processes(args) if args.mode == "processes" else one_seed(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = [int(s) for s in args.seeds.split(",")]
    procs = {}
    for seed in seeds:
        shutil.rmtree(Path(args.runs) / f"seed{seed}", ignore_errors=True)
        log = (Path(args.runs) / f"seed{seed}.log").open("w")
        procs[seed] = subprocess.Popen([sys.executable, __file__, "--one", str(seed), "--runs", args.runs,
                                        "--seconds", str(args.seconds), "--env-steps", str(args.env_steps),
                                        "--device", args.device, "--mode", args.mode, "--out", str(out)]
                                       + [a for item in args.set for a in ("--set", item)],
                                       stdout=log, stderr=subprocess.STDOUT)
    codes = {seed: proc.wait() for seed, proc in procs.items()}
    results = {"recipe": RECIPE, "set": args.set, "mode": args.mode, "method": METHOD, "seconds": args.seconds, "env_steps_budget": args.env_steps,
               "exit_codes": codes, "seeds": {}}
    with (out / "train.log").open("w") as merged:
        for seed in seeds:
            run_dir = Path(args.runs) / f"seed{seed}"
            merged.write(f"===== seed {seed} (exit {codes[seed]})\n")
            merged.write((Path(args.runs) / f"seed{seed}.log").read_text(errors="replace"))
            for name in ("learner", "replay-server", "w0"):  # processes mode: the components' own logs
                log = run_dir / "logs" / f"{name}.log"
                if log.exists():
                    merged.write(f"----- {name}.log, its last 30 lines\n")
                    merged.write("\n".join(log.read_text(errors="replace").splitlines()[-30:]) + "\n")
            final = run_dir / "checkpoints" / "final.safetensors"
            if final.exists():
                shutil.copy(final, out / f"seed{seed}.safetensors")
            if (run_dir / "summary.json").exists():
                results["seeds"][seed] = json.loads((run_dir / "summary.json").read_text())
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print(json.dumps({s: {k: r[k] for k in ("wall_s", "env_steps", "updates")} for s, r in results["seeds"].items()}))
    return 0 if all(c == 0 for c in codes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
