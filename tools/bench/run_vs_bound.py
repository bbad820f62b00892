"""``laneshift bench run-vs-bound``: a whole run's env steps/s against the bound its learner allows
(the figure ``bench all`` reports as ``run_vs_bound_*``; the target is at least 0.9 of the bound,
docs/performance.md). Its old name, ``bench p1``, still runs it (hidden from the command list) and says the
new one.

At replay ratio R (``replay.samples_per_insert``) and batch B, a run can make at most
``bare updates/s x B / R`` env steps/s, where ``bare updates/s`` is a bare torch loop's rate with
the same network, batch and optimizer (``laneshift bench learner``, case mlp-b256). This machine's
speed drifts from minute to minute (up to 2x), so a bound measured once says little about a run
measured ten minutes later: the bare loop runs before every run and after the last (bare, run,
bare, run, bare), and each run is set against the mean of the two measurements beside it.

A run's rate is read from its learner's ``metrics.jsonl`` (``bench run``): over the whole of
training, and over its last two thirds (the steady state, past the replay's fill to min_size and
the first weights' trip to the workers). Both fractions are reported; the steady one is the figure.

    laneshift bench run-vs-bound                     # 2 rounds of 40,000 env steps at ratio 32
    laneshift bench run-vs-bound --rounds 3 --json
    laneshift bench run-vs-bound --train-args "--workers 2 --set actor.envs_per_worker=4"

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from typing import Any

from .run import bench_run
from .suite import BATCH, MAX_BARE_DRIFT, bare_drift, bare_updates_per_s, learner_bound


def _r(x: float | None) -> float | None:
    return round(x, 1) if x is not None else None


def bench_run_vs_bound(rounds: int = 2, env_steps: int = 40_000, ratio: float = 32.0,
                       train_args: str = "--workers 2", seconds: float = 3.0) -> dict:
    if rounds < 1:
        raise SystemExit("bench run-vs-bound: --rounds must be at least 1")
    args = f"--scenario straight {train_args} --env-steps {env_steps} --set replay.samples_per_insert={ratio:g}"
    bares = [bare_updates_per_s(seconds, said_by="bench run-vs-bound")]
    rows: list[dict[str, Any]] = []
    for i in range(rounds):
        run = bench_run(args)
        bares.append(bare_updates_per_s(seconds, said_by="bench run-vs-bound"))
        before, after = bares[i], bares[i + 1]
        row: dict[str, Any] = {"round": i + 1, "rc": run.get("rc"), "bare_before": _r(before), "bare_after": _r(after)}
        if before and after and run.get("rc") == 0:
            bound = learner_bound(before, after, ratio)
            steady, whole = run.get("steady_env_steps_per_s"), run.get("training_env_steps_per_s")
            drift = bare_drift(before, after)
            row.update({"bound_env_steps_per_s": round(bound, 1), "bare_drift": round(drift, 3),
                        "resolved": drift <= MAX_BARE_DRIFT, "steady_env_steps_per_s": steady,
                        "steady_updates_per_s": run.get("steady_updates_per_s"),
                        "training_env_steps_per_s": whole,
                        "steady_fraction": round(steady / bound, 2) if steady else None,
                        "whole_fraction": round(whole / bound, 2) if whole else None,
                        "workers_rate_limited_share": run.get("workers_rate_limited_share"),
                        "learner_sample_wait_share": run.get("learner_sample_wait_share"),
                        "peak_tree_rss_mb": run.get("peak_tree_rss_mb")})
        else:
            row["error"] = run.get("error") or "a bare loop measurement failed"
        rows.append(row)
    return {"train_args": args, "ratio": ratio, "batch": BATCH, "rounds": rows, "max_bare_drift": MAX_BARE_DRIFT,
            "run_vs_bound_steady_fraction": _spread(r.get("steady_fraction") for r in rows),
            "run_vs_bound_whole_fraction": _spread(r.get("whole_fraction") for r in rows),
            # Only the rounds whose bound held still (the bare loop before and after within MAX_BARE_DRIFT).
            "rounds_resolved": sum(1 for r in rows if r.get("resolved")),
            "run_vs_bound_steady_fraction_resolved": _spread(r.get("steady_fraction") for r in rows if r.get("resolved"))}


def _spread(values: Any) -> dict | None:
    xs = [x for x in values if x]
    return {"min": min(xs), "median": statistics.median(xs), "max": max(xs)} if xs else None


def _pct(x: float | None) -> str:
    return f"{x:.0%}" if x is not None else "-"


def render(r: dict) -> str:
    lines = [f"laneshift train --local {r['train_args']}  (bound = bare updates/s x {r['batch']} / {r['ratio']:g})",
             f"  {'round':>5} {'bare before':>12} {'bare after':>11} {'bound':>8} {'steady':>8} {'of bound':>9} "
             f"{'whole':>8} {'of bound':>9} {'workers limited':>16} {'learner waits':>14} {'bare drift':>11}"]
    for row in r["rounds"]:
        if "error" in row:
            lines.append(f"  {row['round']:>5} {row['error']}")
            continue
        lines.append(f"  {row['round']:>5} {row['bare_before']:>12} {row['bare_after']:>11} {row['bound_env_steps_per_s']:>8} "
                     f"{row['steady_env_steps_per_s']:>8} {row['steady_fraction']:>9} {row['training_env_steps_per_s']:>8} "
                     f"{row['whole_fraction']:>9} {_pct(row.get('workers_rate_limited_share')):>16} "
                     f"{_pct(row.get('learner_sample_wait_share')):>14} "
                     f"{_pct(row.get('bare_drift')) + ('' if row.get('resolved') else ' (!)'):>11}")
    lines.append(f"  run vs bound (steady, last two thirds of training): {r['run_vs_bound_steady_fraction']}; whole window: {r['run_vs_bound_whole_fraction']}")
    lines.append(f"  rounds whose bare loop before and after agree within {r['max_bare_drift']:.0%}: {r['rounds_resolved']} "
                 f"of {len(r['rounds'])}; run vs bound over them: {r['run_vs_bound_steady_fraction_resolved']}"
                 + ("" if r["rounds_resolved"] == len(r["rounds"]) else "  ((!): the machine's speed moved; that "
                                                                      "round's fraction says little)"))
    return "\n".join(lines)


def run_vs_bound_main(args: argparse.Namespace) -> int:
    result = bench_run_vs_bound(args.rounds, args.env_steps, args.ratio, args.train_args, args.seconds)
    print(json.dumps(result, indent=2) if args.json else render(result))
    return 0 if all("error" not in r for r in result["rounds"]) else 1


#: The command's name before it said what it measures (``p1`` was the prefix of the figure's keys, not the measurement).
OLD_NAME = "p1"


def _old_name_main(args: argparse.Namespace) -> int:
    print(f"laneshift bench {OLD_NAME} is now `laneshift bench run-vs-bound`", file=sys.stderr, flush=True)
    return run_vs_bound_main(args)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run-vs-bound", help="a whole run's env steps/s against its learner's bound, the bare loop "
                                            "measured before and after every run",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    _add_arguments(p)
    p.set_defaults(func=run_vs_bound_main)
    # The old name: no help= keeps it out of `laneshift bench --help`; ``renamed_to`` marks it as an alias.
    old = sub.add_parser(OLD_NAME, description="the old name of `laneshift bench run-vs-bound`",
                         formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    _add_arguments(old)
    old.set_defaults(func=_old_name_main, renamed_to="laneshift bench run-vs-bound")


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rounds", type=int, default=2, help="runs, each between two bare-loop measurements")
    p.add_argument("--env-steps", type=int, default=40_000, help="each run's budget")
    p.add_argument("--ratio", type=float, default=32.0, help="replay.samples_per_insert of the runs")
    p.add_argument("--train-args", default="--workers 2",
                   help="more arguments for `laneshift train --local` (not --run-dir, --env-steps)")
    p.add_argument("--seconds", type=float, default=3.0, help="seconds per bare-loop measurement")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
