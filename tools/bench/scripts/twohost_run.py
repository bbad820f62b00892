"""A benchmark, not a test: two-host throughput vs local mode, the same run (straight, 2 workers)
alternating local, two hosts, local, two hosts. Needs root and `ip netns` (tests/twohost.py, the cluster tests' harness).

    .venv/bin/python tools/bench/scripts/twohost_run.py [ENV_STEPS]     # prints one JSON line per run, then all

Room: the tools (benchmarks: a script run by path from a checkout). May import: anything in laneshift,
the standard library, and the two-host harness of the tests (tests/twohost.py, by path).
"""
import importlib.util, json, subprocess, sys, tempfile, time
from pathlib import Path
spec = importlib.util.spec_from_file_location("twohost", Path(__file__).resolve().parents[3] / "tests" / "twohost.py")
twohost = importlib.util.module_from_spec(spec); sys.modules["twohost"] = twohost; spec.loader.exec_module(twohost)
LS = str(Path(sys.executable).with_name("laneshift"))
STEPS = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
COMMON = ["--workers", "2", "--scenario", "straight", "--env-steps", str(STEPS), "--set", "train.eval_episodes=0"]
PLACE = ['deploy.worker_resources={"laneshift_env": 1}', 'deploy.replay_resources={"laneshift_head": 1}',
         'deploy.learner_resources={"laneshift_head": 1}', 'deploy.router_resources={"laneshift_head": 1}']
results = []
work = Path(tempfile.mkdtemp(prefix="thb"))
for rnd in range(2):
    # local
    rd = work / f"local{rnd}"
    t = time.monotonic()
    p = subprocess.run([LS, "train", "--local", *COMMON, "--run-dir", str(rd)], capture_output=True, text=True, timeout=900)
    s = json.loads((rd / "summary.json").read_text())
    results.append({"mode": "local", "round": rnd, "rc": p.returncode, "wall_s": s["wall_s"], "env_steps": s["env_steps"],
                    "steps_per_s": round(s["env_steps"] / s["wall_s"], 1), "updates": s["learner"].get("updates"),
                    "lost_items": s["replay"]["lost_items"]})
    print(json.dumps(results[-1]), flush=True)
    # two hosts
    with twohost.two_hosts(work / f"th{rnd}") as h:
        rd = work / f"twohost{rnd}"
        args = [str(LS), "train", "--cluster", h.ray_address, *COMMON, "--run-dir", str(rd)]
        for kv in PLACE:
            args += ["--set", kv]
        p = h.run_in_a(args, timeout=900)
        s = json.loads((rd / "summary.json").read_text())
        results.append({"mode": "two-host", "round": rnd, "rc": p.returncode, "wall_s": s["wall_s"],
                        "env_steps": s["env_steps"], "steps_per_s": round(s["env_steps"] / s["wall_s"], 1),
                        "updates": s["learner"].get("updates"), "lost_items": s["replay"]["lost_items"],
                        "placement": {k: v["node_ip"] for k, v in s["placement"].items()}})
        print(json.dumps(results[-1]), flush=True)
        if rnd == 0:
            print("SUMMARY-TEXT-BEGIN\n" + p.stdout[-2500:] + "\nSUMMARY-TEXT-END", flush=True)
print(json.dumps(results))
