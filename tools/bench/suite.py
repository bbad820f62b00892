"""``laneshift bench all``: every benchmark, one JSON object, each peer beside ours.

What it is: runs ``laneshift bench env | replay | learner | worker | shards | run`` one after another, each
as its own process with ``--json`` (so one's memory or threads cannot colour the next), and the
RLlib peer (``tools/bench/scripts/rllib_dqn.py`` in ``.venv-rllib``, built by ``make bench-rllib``) and the
Reverb peer (``tools/bench/scripts/reverb_replay.py`` in ``.venv-reverb``, ``make bench-reverb``) when their
venvs exist. Then it derives the performance targets' figures from them (``targets``;
docs/performance.md lists where each stands):

- ``learner_over_bare*``: the learner's update against a bare torch loop, updates/s (target: at least 0.9x);
- ``run_vs_bound_*``: a run's steady env steps/s against the most its learner allows (the bound: the bare
  loop's updates/s x batch / replay ratio; target: at least 0.9 of it);
- ``run_peak_tree_*``: a run's peak memory, the process tree's RSS and PSS (target: at most 1.2 GB RSS);
- ``startup_first_stored_s``: seconds from the command to the first transition stored (target: at
  most 5 s);
- ``ingest_per_s_1024_per_message``: replay ingest, transitions/s (target: 1M/s); ``ingest_by_shard_count``: ingest and sample latency
  by replay shard count (docs/scaling.md);
- ``vs_rllib_*``, ``vs_reverb_*``, ``reverb_*``: laneshift against RLlib's DQN and Reverb.

Nothing is estimated: a figure whose benchmark did not run is ``null`` with the reason. One thing
is measured twice on purpose: the bare loop runs again right after the whole run
(``bare_after_run``), and the bound is the mean of the two, because this machine's speed drifts
between minutes (``bench run-vs-bound`` does the same for each of its runs).

Room: the tools (benchmarks). May import: the contract (``laneshift.config``); every benchmark runs as a
``laneshift bench ...`` subprocess and each peer in its own venv.

    laneshift bench all --out docs/results/bench-all.json      # about 10 minutes here
    laneshift bench all --quick                                  # shorter windows, about 4 minutes
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from laneshift.config import ReplayConfig

#: The run the end-to-end figures come from: ``make train``'s shape without its demo phase.
RUN_ARGS = "--workers 2 --scenario straight --env-steps {steps}"


def _last_json(text: str) -> dict:
    """The last top-level JSON object of a command's stdout (Ray's raylet may print lines of its
    own before it; the object's nested lines are indented, so its first line starts with "{")."""
    text = text.strip()
    start = text.rfind("\n{")
    return json.loads(text[start + 1:] if start >= 0 else text)


def _bench(name: str, args: list[str], timeout_s: float, said_by: str = "bench all") -> dict:
    """One ``laneshift bench NAME --json`` in its own process: its JSON, or why there is none."""
    cmd = [sys.executable, "-m", "laneshift", "bench", name, *args, "--json"]
    started = time.monotonic()
    print(f"{said_by}: {name} ...", file=sys.stderr, flush=True)
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s,
                              env={**os.environ, "LANESHIFT_PROGRESS": "0"})
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout_s:.0f} s", "command": " ".join(cmd[1:])}
    try:
        result = _last_json(done.stdout)
    except ValueError:
        return {"error": f"rc {done.returncode}, no JSON", "stderr_tail": done.stderr[-600:], "command": " ".join(cmd[1:])}
    print(f"{said_by}: {name} done in {time.monotonic() - started:.0f} s", file=sys.stderr, flush=True)
    return {"command": "laneshift " + " ".join(cmd[3:]), **result}


def _peer(name: str, venv: str, script: str, args: list[str], why_venv: str, timeout_s: float,
          env: dict[str, str] | None = None) -> dict:
    """A peer benchmark in its own venv (``make bench-<name>`` builds it): its JSON, or why none."""
    root = Path(__file__).resolve().parents[2]  # the repo: tools/bench/suite.py
    python, path = root / venv / "bin" / "python", root / "tools" / "bench" / "scripts" / script
    if not python.exists() or not path.exists():
        return {"skipped": f"no {venv} here: `make bench-{name}` builds it ({why_venv})"}
    print(f"bench all: {name} ...", file=sys.stderr, flush=True)
    try:
        done = subprocess.run([str(python), str(path), *args], capture_output=True, text=True, timeout=timeout_s,
                              cwd=root, env={**os.environ, **(env or {})})
        return {"command": f"{venv}/bin/python tools/bench/scripts/{script} {' '.join(args)}", **_last_json(done.stdout)}
    except (subprocess.TimeoutExpired, ValueError) as exc:
        return {"error": f"{type(exc).__name__}: {exc}"}


#: learner.batch_size's default, and the bare loop's case (mlp-b256).
BATCH = 256


#: A run-vs-bound figure (a run against its learner's bound) says something only when the bare loop measured
#: before and after its run agree within this: the target's own margin is 10 % (0.9 of the bound),
#: and on the 2-core VM these benchmarks were written on the bare loop once measured 138.5 updates/s
#: just before a run and 220.6 right after it (`laneshift bench run-vs-bound` shows both; docs/performance.md).
#: A round beyond it is reported, flagged, and left out of ``bench run-vs-bound``'s resolved summary.
MAX_BARE_DRIFT = 0.10


def bare_drift(before: float | None, after: float | None) -> float | None:
    """How far apart the two bare-loop measurements beside a run are (larger / smaller - 1)."""
    if not before or not after:
        return None
    return max(before, after) / min(before, after) - 1


def learner_bound(before: float, after: float | None, ratio: float) -> float:
    """The run-vs-bound bound: the env steps/s a run at replay ratio ``ratio`` can make at most, from the bare
    loop's updates/s measured before it and, if that ran, after it (their mean: the machine drifts
    between minutes), times the batch over the ratio."""
    bare = (before + after) / 2 if after else before
    return bare * BATCH / ratio


def _mlp_case(learner: dict) -> dict:
    """The mlp-b256 case of a ``bench learner`` result ({} if it did not run)."""
    cases = learner.get("cases")
    return next((c for c in cases if c.get("name") == "mlp-b256"), {}) if isinstance(cases, list) else {}


def bare_updates_per_s(seconds: float, said_by: str = "bench all") -> float | None:
    """The bare torch loop's updates/s (``bench learner --cases mlp-b256``, its own process)."""
    r = _bench("learner", ["--cases", "mlp-b256", "--seconds", str(seconds), "--rounds", "2"], 600, said_by=said_by)
    return _get(_mlp_case(r), "bare", "updates_per_s")


def _rllib(steps: int, timeout_s: float) -> dict:
    return _peer("rllib", ".venv-rllib", "rllib_dqn.py", ["--env-steps", str(steps)],
                 "RLlib pins gymnasium 1.2.2", timeout_s)


def _reverb(duration: str, capacity: str, timeout_s: float) -> dict:
    """The replay peer: Reverb under the load of ``bench shards --shards 1`` (tools/bench/scripts/reverb_replay.py)."""
    return _peer("reverb", ".venv-reverb", "reverb_replay.py", ["--duration", duration, "--capacity", capacity],
                 "Reverb needs TensorFlow 2.15, numpy<2", timeout_s, env={"TF_CPP_MIN_LOG_LEVEL": "2"})


def _get(d: dict, *path: str):
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return None
        d = d[key]
    return d


def _ratio(shard_rows: list | None, theirs: float | None) -> float | None:
    """Our one-shard ingest over the peer's (the p7 row whose load the peer ran)."""
    ours = next((row.get("ingest_per_s") for row in shard_rows or [] if row.get("shards") == 1), None)
    return round(ours / theirs, 1) if ours and theirs else None


def derive(r: dict) -> dict:
    """The targets' figures (the module's text lists them) from the benchmarks' own outputs (null
    where one did not run)."""
    learner = _mlp_case(r["learner"])
    bare = _get(learner, "bare", "updates_per_s")
    after = _get(r, "bare_after_run", "updates_per_s")
    run, peer = r["run"], r["peers"]["rllib"]
    # RUN_ARGS leaves replay.samples_per_insert at its default: the run's replay ratio.
    bound = learner_bound(bare, after, ratio=ReplayConfig().samples_per_insert) if bare else None
    drift = bare_drift(bare, after)
    ours = run.get("training_env_steps_per_s")  # the whole of training, as RLlib's figure is read
    steady = run.get("steady_env_steps_per_s")  # its last two thirds: run-vs-bound's (bench run-vs-bound repeats it in rounds)
    theirs = peer.get("env_steps_per_s") if isinstance(peer, dict) else None
    return {
        "learner_over_bare": round(learner["learner_over_bare"], 2) if learner.get("learner_over_bare") else None,
        "learner_over_bare_cpu": round(learner["learner_over_bare_cpu"], 2) if learner.get("learner_over_bare_cpu") else None,
        "run_vs_bound_env_steps_per_s": steady, "run_vs_bound_bound_env_steps_per_s": round(bound, 1) if bound else None,
        "run_vs_bound_fraction_of_bound": round(steady / bound, 2) if steady and bound else None,
        "run_vs_bound_whole_training_fraction_of_bound": round(ours / bound, 2) if ours and bound else None,
        # The bare loop before and after the run, and whether they agree within MAX_BARE_DRIFT.
        "run_vs_bound_bare_before_after": [round(bare, 1) if bare else None, round(after, 1) if after else None],
        "run_vs_bound_bound_resolved": drift is not None and drift <= MAX_BARE_DRIFT,
        "run_peak_tree_rss_mb": run.get("peak_tree_rss_mb"), "run_peak_tree_pss_mb": run.get("peak_tree_pss_mb"),
        "startup_first_stored_s": run.get("first_stored_s"),
        "vs_rllib_env_steps": round(ours / theirs, 1) if ours and theirs else None,
        "vs_rllib_rss": round(run["peak_tree_rss_mb"] / peer["peak_tree_rss_mb"], 2)
        if run.get("peak_tree_rss_mb") and isinstance(peer, dict) and peer.get("peak_tree_rss_mb") else None,
        "ingest_per_s_1024_per_message": (_get(r, "ingest_1024", "rows") or [{}])[0].get("ingest_per_s"),
        # The replay peer, under the load of the p7 row with one shard.
        "vs_reverb_ingest": _ratio(_get(r, "shards", "rows"), _get(r, "peers", "reverb", "ingest_per_s")),
        "reverb_ingest_per_s": _get(r, "peers", "reverb", "ingest_per_s"),
        "reverb_sample_p99_idle_ms": _get(r, "peers", "reverb", "sample_idle", "p99_ms"),
        # Ingest and sample latency by shard count (docs/scaling.md).
        "ingest_by_shard_count": [
            {k: row.get(k) for k in ("shards", "ingest_per_s", "server_cpu_us_per_transition")}
            | {"sample_p99_idle_ms": _get(row, "sample_idle", "p99_ms"),
               "sample_p99_under_ingest_ms": _get(row, "sample_under_ingest", "p99_ms"),
               # A zero-work queryable's p99 beside it: what the transport and machine leave.
               "floor_p99_idle_ms": _get(row, "floor_idle", "p99_ms"),
               "floor_p99_under_ingest_ms": _get(row, "floor_under_ingest", "p99_ms")}
            for row in _get(r, "shards", "rows") or []],
    }


def bench_all(quick: bool) -> dict:
    seconds, steps = ("1", 10_000) if quick else ("3", 20_000)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[1]).stdout.strip()
    result: dict = {"revision": rev or None, "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
                    "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                                "python": platform.python_version()}}
    result["env"] = _bench("env", ["--steps", "600" if quick else "2000"], 600)
    result["replay"] = _bench("replay", ["--duration", seconds, "--actors", "2,8"] if quick else [], 900)
    result["learner"] = _bench("learner", ["--seconds", seconds, "--rounds", "2", "--cases", "mlp-b256,cnn-b32"], 900)
    result["worker"] = _bench("worker", ["--steps", "4000" if quick else "8000"], 600)
    result["shards"] = _bench("shards", ["--shards", "1,2,4", "--duration", seconds,
                                         "--capacity", "100000" if quick else "400000"], 900)
    # The ingest target, 1M transitions/s (p2): one shard fed 1,024 transitions per message (a
    # vectorised actor's send), the size at which this machine's 2 cores reach it (32 per message:
    # the p7 rows above).
    result["ingest_1024"] = _bench("shards", ["--shards", "1", "--batch", "1024", "--duration", seconds,
                                              "--capacity", "500000" if quick else "2000000"], 900)
    result["run"] = _bench("run", ["--train-args", RUN_ARGS.format(steps=steps)], 900)
    # The bare loop again right after the run, as `bench run-vs-bound` does: the bound is the mean of the two.
    result["bare_after_run"] = {"updates_per_s": bare_updates_per_s(float(seconds))}
    result["peers"] = {"rllib": _rllib(steps // 2, 1800),
                       "reverb": _reverb(seconds, "100000" if quick else "400000", 900)}
    result["targets"] = derive(result)
    return result


def bench_all_main(args: argparse.Namespace) -> int:
    result = bench_all(args.quick)
    text = json.dumps(result, indent=2)
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)
    return 0 if not any(isinstance(v, dict) and "error" in v for v in result.values()) else 1


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("all", help="every benchmark and the RLlib peer, as one JSON object with the "
                                   "performance targets' figures",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--quick", action="store_true", help="shorter windows and runs (about 4 minutes instead of 10)")
    p.add_argument("--out", help="also write the JSON to this file")
    p.set_defaults(func=bench_all_main)
