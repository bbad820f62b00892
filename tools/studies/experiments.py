"""``laneshift experiment compare``: the paper's Table 2 comparison, reproducibly.

Every method is trained with the same budget and seeds through the real local system (Ray
workers, zenoh, replay-server and learner processes), then its final network is evaluated
greedily from both initial-lane settings; the baseline drivers are evaluated on the same episode
seeds. A method's rate is the mean of its per-seed rates with a 95 % percentile bootstrap
interval over seeds (``laneshift.tools.studies.stats``); the rate pooled over all evaluation episodes
with its Wilson interval is kept beside it, labelled pooled (it treats the episodes of different
seeds as independent, so it understates the uncertainty).

    laneshift experiment compare --scenario straight --methods none,retention,rehearsal,dqfd \\
        --seeds 0,1,2 --env-steps 150000 --eval-episodes 200 --out runs/exp-table2
    laneshift experiment replot --results docs/results/table2-v2

Methods: ``none``, ``retention``, ``rehearsal`` (the paper), ``dqfd`` (beyond the paper: a
demo-only pre-training phase, then retention, with DQfD's large-margin loss on demo rows and
10-step returns), ``dqfd-bc`` (``dqfd`` plus a cross-entropy imitation loss on demo rows and a
dueling head). Writes ``results.json``, ``table.md``, ``table2.png`` (bars with across-seed
intervals), ``episodes.json`` (every run's per-episode data, so the curves can be redrawn once the
run dirs are gone), ``curves_env_steps.png`` / ``curves_episodes.png`` / ``curves_wallclock.png``
(moving-average return and episode length, mean over seeds with a 95 % bootstrap band; no env-step
figure for logs without env steps) and, for runs with ``train.eval_every``, ``curves_eval.png``
(greedy survival and achievement during training). ``replot`` redraws the table and figures of a
study from its ``results.json`` and ``episodes.json`` (or the runs' ``metrics.jsonl``).

This module is the two commands; what they use is a module each: ``runs`` (the training runs and
what they leave), ``table2`` (the numbers and the table), ``plots`` (the figures).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from typing import Any

from laneshift.checkpoints import run_checkpoint
from laneshift.config import METHODS, ConfigError, load_run_config, method_settings
from laneshift.progress import progress, write
from laneshift.tools.argtypes import add_set_arg, parse_set, positive_int, seed_list
from laneshift.tools.studies.evaluate import evaluate_lanes, load_greedy_policy
from laneshift.tools.studies.plots import plot_curves, plot_table2
from laneshift.tools.studies.runs import EPISODES_FILE, collect_episodes, method_config, train_logged, write_episodes
from laneshift.tools.studies.table2 import HUMAN_LIKE_ROW, human_like_lanes, lane_stats, pooled, render_table


def run_compare(args: argparse.Namespace) -> dict:
    user = parse_set(args.set)
    base = load_run_config(args.config, {"env.scenario": args.scenario, "actor.workers": args.workers, **user})
    methods, seeds = _names(args.methods), seed_list(args.seeds)
    out_dir = Path(args.out).resolve()
    # Every run's config before the first run starts: a bad method, seed or --set fails now, not hours in.
    configs = {(m, s): method_config(base, m, s, out_dir / f"{m}-s{s}", args.env_steps, user)
               for m in methods for s in seeds}
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"scenario": args.scenario, "env_steps": args.env_steps, "seeds": seeds,
                               "eval_episodes": args.eval_episodes, "eval_max_steps": args.eval_max_steps,
                               "methods": {}, "baselines": {}}
    eval_seed = 100_000  # the same evaluation episodes for every method and baseline
    # "human-like": the stand-in for the paper's human driver (laneshift.tools.demos.humanlike; not a person).
    drivers = ("random", "keep-lane", "scripted", "human-like") if args.baselines else ()
    overall = progress(total=len(configs) + len(drivers), desc="compare", unit="run")
    for method in methods:
        runs = []
        for seed in seeds:
            run_dir = out_dir / f"{method}-s{seed}"
            cfg = configs[(method, seed)]
            started = time.monotonic()
            train_logged(cfg, out_dir / f"{method}-s{seed}.log", label=f"train {method} seed {seed}")
            greedy = load_greedy_policy(run_checkpoint(run_dir))
            evals = evaluate_lanes(lambda env: greedy, dataclasses.replace(cfg.env, max_steps=args.eval_max_steps),
                                   args.eval_episodes, eval_seed, progress=f"eval {method} seed {seed}")
            runs.append({"seed": seed, "run_dir": str(run_dir), "wall_s": round(time.monotonic() - started, 1),
                         "eval": evals})
            write(f"experiment: {method} seed {seed}: " + ", ".join(
                f"{lane} survival {e['survival_rate']:.0%} achievement {e['achievement_rate']:.0%}"
                for lane, e in evals.items()))
            overall.update()
        results["methods"][method] = {"runs": runs, **lane_stats(runs)}
    if args.baselines:
        from laneshift.actors.envs.demonstrator import KeepLaneDriver, ScriptedDriver

        def random_driver(env):
            env.action_space.seed(eval_seed)  # the random baseline's actions are reproducible too
            return lambda obs: env.action_space.sample()

        makers = {"random": random_driver, "keep-lane": KeepLaneDriver, "scripted": ScriptedDriver}
        n_base = args.eval_episodes * len(seeds)
        for name in drivers:
            env_cfg = dataclasses.replace(base.env, max_steps=args.eval_max_steps)
            if name == "human-like":
                evals = human_like_lanes(env_cfg, n_base, eval_seed)
                name = HUMAN_LIKE_ROW
            else:
                evals = evaluate_lanes(makers[name], env_cfg, n_base, eval_seed, progress=f"baseline {name}")
            results["baselines"][name] = {lane: {"survival": pooled([e], "survival_rate"),
                                                 "achievement": pooled([e], "achievement_rate")}
                                          for lane, e in evals.items()}
            overall.update()
    overall.close()
    (out_dir / "results.json").write_text(json.dumps(results, indent=2))
    (out_dir / "table.md").write_text(render_table(results))
    plot_table2(results, out_dir)
    episodes, _ = collect_episodes(results, out_dir)
    if episodes:
        write_episodes(episodes, out_dir)
    plot_curves(results, out_dir, episodes=episodes)
    print(render_table(results))
    return results


def _names(text: str) -> list[str]:
    """``--methods``: comma separated, each one known."""
    methods = [m.strip() for m in text.split(",") if m.strip()]
    if not methods:
        raise ConfigError(f"--methods: name at least one of {', '.join(METHODS)}")
    for m in methods:
        method_settings(m, "--methods")
    return methods


def _read_results(results_dir: Path, flag: str) -> dict:
    """A compare study's results.json, or exit with one line saying what is wrong with it."""
    path = results_dir / "results.json"
    if not path.is_file():
        raise SystemExit(f"{flag} {results_dir}: no results.json there (name a dir written by "
                         f"`laneshift experiment compare`)")
    try:
        results = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"{flag} {results_dir}: results.json is not readable JSON ({exc})") from None
    if not (isinstance(results, dict) and isinstance(results.get("methods"), dict)
            and isinstance(results.get("baselines"), dict) and "scenario" in results):
        raise SystemExit(f"{flag} {results_dir}: results.json is not from `laneshift experiment compare`")
    return results


#: What two studies must share for their runs to be one study's seeds.
SAME_STUDY = ("scenario", "env_steps", "eval_episodes", "eval_max_steps")


def merge_studies(results: dict, more: dict, where: str) -> None:
    """Add ``more``'s runs (other seeds of the same methods, budget and evaluation) to ``results``,
    and recompute each method's numbers over all its seeds; baselines ``results`` lacks are taken."""
    differ = [k for k in SAME_STUDY if results.get(k) != more.get(k)]
    if differ:
        raise SystemExit(f"--add {where}: not the same study ({', '.join(f'{k} {results.get(k)} vs {more.get(k)}' for k in differ)})")
    for method, body in more["methods"].items():
        runs = results["methods"].setdefault(method, {"runs": []})["runs"]
        seen = {r["seed"] for r in runs}
        twice = sorted(seen & {r["seed"] for r in body["runs"]})
        if twice:
            raise SystemExit(f"--add {where}: {method} seed(s) {twice} are in both studies")
        runs += body["runs"]
        runs.sort(key=lambda r: r["seed"])
        results["methods"][method] = {"runs": runs, **lane_stats(runs)}
    results["seeds"] = sorted({r["seed"] for body in results["methods"].values() for r in body["runs"]})
    for name, body in more["baselines"].items():
        results["baselines"].setdefault(name, body)


def run_replot(args: argparse.Namespace) -> int:
    """Redraw a study's table and figures from what it kept, without training (``--add``: with the
    seeds of other studies of the same setting merged in, written as this study's results.json)."""
    results_dir = Path(args.results)
    results = _read_results(results_dir, "--results")
    out_dir = Path(args.out) if args.out else results_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    episodes, from_runs = collect_episodes(results, results_dir)
    for extra in args.add or []:
        more = _read_results(Path(extra), "--add")
        merge_studies(results, more, extra)
        more_episodes, _ = collect_episodes(more, Path(extra))
        episodes.update(more_episodes)
        from_runs = from_runs or bool(more_episodes)
    if args.add:
        (out_dir / "results.json").write_text(json.dumps(results, indent=2))
        written.append(out_dir / "results.json")
    if results["methods"]:
        (out_dir / "table.md").write_text(render_table(results))
        written += [out_dir / "table.md", plot_table2(results, out_dir)]
    if episodes:
        if from_runs:
            written.append(write_episodes(episodes, out_dir))
        written += plot_curves(results, out_dir, args.window, episodes)
    else:
        write(f"replot: no per-episode data for any run ({EPISODES_FILE} or the runs' metrics.jsonl): "
              f"learning-curve figures left as they are")
    for p in written:
        write(f"replot: wrote {p}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("compare", help="train and evaluate methods x seeds (the paper's Table 2)")
    p.add_argument("--scenario", default="straight", help="straight | merge | curve | roundabout")
    p.add_argument("--methods", default="none,retention,rehearsal,dqfd", help=f"comma separated: {', '.join(METHODS)}")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated training seeds: one run per method and seed")
    p.add_argument("--env-steps", type=positive_int, default=150_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--eval-episodes", type=positive_int, default=200, help="greedy evaluation episodes per seed and initial lane")
    p.add_argument("--eval-max-steps", type=positive_int, default=300, help="evaluation episode length (paper: 300)")
    p.add_argument("--no-baselines", dest="baselines", action="store_false",
                   help="skip the random, keep-lane, scripted and human-like stand-in driver baselines")
    p.add_argument("--out", default="runs/experiment", help="where the runs, results.json, table.md and plots go")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_compare(a), 0)[1])
    p = subparsers.add_parser("replot", help="redraw a compare study's table and figures from its kept data, "
                                             "without training")
    p.add_argument("--results", required=True, metavar="DIR",
                   help="a dir with the results.json of `laneshift experiment compare` (e.g. docs/results/table2-v2); "
                        f"curves need its {EPISODES_FILE} or the runs' metrics.jsonl")
    p.add_argument("--out", metavar="DIR", help="where table.md and the figures go (default: the --results dir)")
    p.add_argument("--window", type=positive_int, default=100, help="episodes in the curves' moving average")
    p.add_argument("--add", action="append", metavar="DIR",
                   help="another compare study of the same scenario, budget and evaluation whose seeds join "
                        "this one's (repeatable); the merged results.json is written to --out")
    p.set_defaults(func=run_replot)
