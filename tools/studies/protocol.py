"""``laneshift experiment protocol``: the whole evaluation protocol for one method on one road, in
one command.

Per training seed (default 0, 1, 2) one run through the real local system (Ray workers, zenoh,
replay-server and learner processes), greedily evaluated every ``--validation-every`` env steps on
validation episodes (episode seeds from 200,000: ``train.validation_seed``); then the run's FINAL
network (no checkpoint is chosen) is evaluated greedily on the test episodes (episode seeds from
100,000, never used for any choice; ``--test-episodes`` per initial-lane setting, ``--eval-max-steps``
steps each). The scripted driver and the human-like stand-in drive the same test episodes. A learned
rate is the mean of the per-seed rates with a 95 % percentile bootstrap interval over seeds
(``laneshift.tools.studies.stats``, through ``table2.across_seeds``).

    laneshift experiment protocol --scenario straight --method dqfd-bc --seeds 0,1,2 \\
        --env-steps 600000 --publish results/checkpoints

Resumable: the same command again skips every seed whose ``<method>-s<seed>.json`` exists, continues
a seed whose run stopped unfinished (as ``laneshift train --resume`` does) and evaluates one whose
run finished but was not evaluated; the baselines are kept in ``baselines.json``. Writes to
``--out`` (default ``runs/protocol/<road>-<method>``): each seed's run dir, training log and
``<method>-s<seed>.json`` (test evaluation, validation curve, resolved config, git revision),
``results.json`` (in ``experiment compare``'s layout too, so ``experiment replot`` reads it),
``table.md`` (test rates beside the baselines; per seed the first time the validation achievement
reached 80 % and 95 %, and its largest drop below its running best after reaching
``--stability-target``) and ``curves_validation.png``. ``--publish DIR``: each seed's final network
as ``DIR/<road>-<method>-seed<N>-final.safetensors`` with a ``.json`` beside it (command line, git
revision, resolved config, test table and the ``laneshift eval`` commands that reproduce it).

``--scenario allroads`` trains one network for the four roads and tests it on each road's own test
episodes (the single-road protocol's, the road pinned with ``env.road``), the drivers on the same
episodes, one table row per road and initial lane (``laneshift.tools.studies.allroads``); its published
JSON holds the per-road ``laneshift eval`` commands.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml

from laneshift.tools.argtypes import add_set_arg, fraction, non_negative_int, parse_set, positive_int
from laneshift.config import METHODS, ConfigError, EnvConfig, RunConfig, load_run_config, method_settings
from laneshift.progress import progress, write
from laneshift.tools.studies import allroads
from laneshift.tools.studies.evaluate import INITIAL_LANES, evaluate_lanes, load_greedy_policy
from laneshift.tools.argtypes import seed_list
from laneshift.tools.studies.plots import plot_eval_curves
from laneshift.tools.studies.runs import method_config, metrics_records, train_logged
from laneshift.tools.studies.table2 import HUMAN_LIKE_ROW, across_seeds, human_like_lanes, lane_stats, pooled
from laneshift.tools.studies.stats import RESAMPLES

#: The test episodes: episode i of each initial-lane setting is reset with seed TEST_SEED + i.
TEST_SEED = 100_000
#: The validation episodes of the greedy evaluation during training (``train.validation_seed``).
VALIDATION_SEED = 200_000
#: Validation achievement levels whose first crossing the table reports, per seed.
THRESHOLDS = (0.80, 0.95)
SCENARIOS = ("straight", "merge", "curve", "roundabout")
#: ``--scenario``'s choices: a road, or one network for all four.
SCENARIO_CHOICES = (*SCENARIOS, "allroads")
#: The scripted driver's row name (``laneshift.actors.envs.demonstrator.ScriptedDriver``).
SCRIPTED_ROW = "scripted"
BASELINES_FILE = "baselines.json"


# ---------------------------------------------------------------------------- curve measures


def time_to_threshold(curve: list[dict], threshold: float, key: str = "achievement_rate") -> dict | None:
    """The first validation evaluation whose ``key`` reached ``threshold``: its ``env_steps`` and
    ``elapsed_s`` (None if the record has none); None if no evaluation reached it."""
    for rec in curve:
        if rec.get(key) is not None and rec[key] >= threshold:
            return {"env_steps": rec["env_steps"], "elapsed_s": rec.get("elapsed_s")}
    return None


def stability_drop(curve: list[dict], target: float, key: str = "achievement_rate") -> float | None:
    """The largest drop of ``key`` below its running best, counted from the first evaluation that
    reached ``target`` on (0.0: it never fell below its best since); None if it never reached it."""
    values = [rec[key] for rec in curve if rec.get(key) is not None]
    start = next((i for i, v in enumerate(values) if v >= target), None)
    if start is None:
        return None
    best, drop = values[start], 0.0
    for v in values[start:]:
        best = max(best, v)
        drop = max(drop, best - v)
    return drop


def validation_curve(run_dir: str | Path) -> list[dict]:
    """A run's greedy evaluations during training (``metrics.jsonl`` records of kind ``eval``), in
    order: ``env_steps``, ``elapsed_s`` (wall clock since the run's first metrics record: a resumed
    run's includes its pause), ``episodes``, ``survival_rate``, ``achievement_rate``. Empty without
    a metrics file."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        return []
    t0, curve = None, []
    for rec in metrics_records(path):
        if t0 is None and rec.get("time") is not None:
            t0 = rec["time"]
        if rec.get("kind") != "eval" or rec.get("env_steps") is None:
            continue
        elapsed = rec.get("elapsed_s")
        if elapsed is None and rec.get("time") is not None and t0 is not None:
            elapsed = round(rec["time"] - t0, 1)
        curve.append({"env_steps": rec["env_steps"], "elapsed_s": elapsed, "episodes": rec.get("episodes"),
                      "survival_rate": rec.get("survival_rate"), "achievement_rate": rec.get("achievement_rate")})
    return curve


# ---------------------------------------------------------------------------- provenance


def command_line() -> str:
    """This process's command line, shell-quoted."""
    return shlex.join(sys.argv)


def git_revision(where: str | Path | None = None) -> dict:
    """``{"revision", "dirty"}`` of the git checkout holding ``where`` (default: this code's); both
    None outside a git checkout or without git."""
    where = Path(where) if where is not None else Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=30)
        if head.returncode != 0:
            return {"revision": None, "dirty": None}
        status = subprocess.run(["git", "status", "--porcelain"], cwd=where, capture_output=True, text=True,
                                timeout=60)
        dirty = bool(status.stdout.strip()) if status.returncode == 0 else None
        return {"revision": head.stdout.strip(), "dirty": dirty}
    except (OSError, subprocess.SubprocessError):
        return {"revision": None, "dirty": None}


def eval_command(checkpoint: str | Path, env: dict, episodes: int, max_steps: int, lane: str) -> str:
    """The ``laneshift eval`` command that evaluates ``checkpoint`` on these test episodes: the
    run's env (``env``: its config section as a dict) with ``--set`` for each field that ``eval``
    has no flag for and that differs from the default."""
    defaults = dataclasses.asdict(EnvConfig())
    argv = ["laneshift", "eval", "--checkpoint", str(checkpoint), "--scenario", str(env["scenario"]),
            "--episodes", str(episodes), "--seed", str(TEST_SEED), "--max-steps", str(max_steps),
            "--initial-lane", lane]
    if env.get("observation", defaults["observation"]) != defaults["observation"]:
        argv += ["--observation", str(env["observation"])]
    for name, value in env.items():
        if name in ("scenario", "initial_lane", "max_steps", "observation") or value == defaults.get(name):
            continue
        argv += ["--set", f"env.{name}={json.dumps(value) if isinstance(value, bool) else value}"]
    return shlex.join(argv)


def write_json(path: Path, data: Any) -> None:
    """Written whole or not at all (a seed's file says it is done)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, path)


# ---------------------------------------------------------------------------- the protocol


def road_name(env: EnvConfig, scenario: str) -> str:
    """The published files' road: the scenario, ``-policytraffic`` when other vehicles drive with
    the agent's policy (``env.policy_vehicles``)."""
    return scenario + ("-policytraffic" if env.policy_vehicles > 0 else "")


def held_out(args: argparse.Namespace, env: EnvConfig) -> dict:
    """A seed record's ``test``: the test episodes (allroads: on each of these roads)."""
    test = {"episode_seed": TEST_SEED, "episodes_per_lane": args.test_episodes, "max_steps": args.eval_max_steps}
    return {**test, "roads": list(allroads.ALLROADS)} if env.is_allroads else test


def seed_state(run_dir: Path, record: Path) -> str:
    """``done`` (its json exists), ``trained`` (the run finished, not evaluated yet), ``resume``
    (a run stopped unfinished) or ``new``."""
    if record.is_file():
        return "done"
    if not (run_dir / "config.yaml").is_file():
        return "new"
    try:
        ended = json.loads((run_dir / "summary.json").read_text()).get("ended_by")
    except (OSError, ValueError, AttributeError):
        ended = None
    return "trained" if ended == "done" and (run_dir / "checkpoints" / "final.safetensors").is_file() else "resume"


def plan(args: argparse.Namespace) -> tuple[Path, str, dict[int, RunConfig], dict[int, str]]:
    """(out dir, road, each seed's config, each seed's state): every config is built (and a bad
    method, seed or --set refused) before the first run starts. A seed whose run stopped unfinished
    gets its saved config with this command's settings on top (as ``laneshift train --resume``)."""
    user = parse_set(args.set)
    method_settings(args.method, "--method")
    seeds = seed_list(args.seeds)
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"--seeds: a seed is named twice in {args.seeds!r}")
    if TEST_SEED + args.test_episodes > VALIDATION_SEED:
        raise ConfigError(f"--test-episodes: at most {VALIDATION_SEED - TEST_SEED:,} (the test episodes' seeds "
                          f"from {TEST_SEED:,} would reach the validation episodes' from {VALIDATION_SEED:,})")
    if args.road is not None and (not args.road.strip() or "/" in args.road or args.road != args.road.strip()):
        raise ConfigError(f"--road: a name for file names (no '/', no surrounding spaces), got {args.road!r}")
    every = args.env_steps // 10 if args.validation_every is None else args.validation_every
    shortcuts = {"env.scenario": args.scenario, "actor.workers": args.workers, **user}
    base = load_run_config(args.config, shortcuts)
    protocol = {"train.eval_every": every, "train.periodic_eval_episodes": args.validation_episodes,
                "train.validation_seed": VALIDATION_SEED}

    def config(seed_base: RunConfig, seed: int, run_dir: Path) -> RunConfig:
        cfg = method_config(seed_base, args.method, seed, run_dir, args.env_steps, user)
        return load_run_config(overrides=protocol, base=cfg)

    probe = config(base, seeds[0], Path("probe")).env
    if probe.is_allroads and probe.road:
        raise ConfigError(f"env.road: the allroads protocol trains on all four roads and tests each one; leave "
                          f"env.road empty (got {probe.road!r})")
    road = args.road or road_name(probe, args.scenario)
    out_dir = Path(args.out or f"runs/protocol/{road}-{args.method}").resolve()
    configs, states = {}, {}
    test = held_out(args, probe)
    for seed in seeds:
        run_dir, record = out_dir / f"{args.method}-s{seed}", out_dir / f"{args.method}-s{seed}.json"
        states[seed] = seed_state(run_dir, record)
        if states[seed] == "done":  # a finished seed joins this study only if it is of the same protocol
            try:
                kept = json.loads(record.read_text())
                differ = {"test": (kept["test"], test), "env_steps": (kept["config"]["train"]["env_steps"],
                                                                      args.env_steps)}
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise ConfigError(f"seed {seed}: {record} is not readable ({exc}); remove it to evaluate the "
                                  f"seed again") from None
            differ = {k: v for k, v in differ.items() if v[0] != v[1]}
            if differ:
                raise ConfigError(f"seed {seed}: {record} is of another protocol ("
                                  + ", ".join(f"{k} {v[0]} there, {v[1]} now" for k, v in differ.items())
                                  + "); choose another --out, or remove it to evaluate the seed again")
        seed_base = base
        if states[seed] == "resume":
            try:
                seed_base = load_run_config(run_dir / "config.yaml", shortcuts)
            except ConfigError as exc:
                raise ConfigError(f"seed {seed}: the unfinished run in {run_dir}: {exc}") from None
        configs[seed] = config(seed_base, seed, run_dir)
    return out_dir, road, configs, states


def run_seed(cfg: RunConfig, state: str, args: argparse.Namespace, out_dir: Path, road: str) -> dict:
    """Train (or continue) one seed's run, evaluate its final network on the test episodes, write
    and return its ``<method>-s<seed>.json``."""
    seed, method = cfg.train.seed, args.method
    run_dir = Path(cfg.train.run_dir)
    started = time.monotonic()
    if state in ("new", "resume"):
        try:
            train_logged(cfg, out_dir / f"{method}-s{seed}.log", label=f"train {method} seed {seed}",
                         resume=state == "resume")
        except RuntimeError as exc:  # failed, or stopped (Ctrl-C, SIGTERM) with its checkpoints
            raise SystemExit(f"seed {seed}: {exc}; the same command again continues it") from None
    greedy = load_greedy_policy(run_dir / "checkpoints" / "final.safetensors")
    test_env = dataclasses.replace(cfg.env, max_steps=args.eval_max_steps)
    by_road = None
    if test_env.is_allroads:  # each road's own test episodes; the protocol's numbers pool the four
        by_road = allroads.evaluate_roads(lambda env: greedy, test_env, args.test_episodes, TEST_SEED,
                                          progress=f"test {method} seed {seed}")
        evals = allroads.pooled_roads(by_road)
    else:
        evals = evaluate_lanes(lambda env: greedy, test_env, args.test_episodes, TEST_SEED,
                               progress=f"test {method} seed {seed}")
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, ValueError):
        summary = {}
    config = yaml.safe_load((run_dir / "config.yaml").read_text())  # the run's resolved config
    t = config["train"]
    record = {"seed": seed, "method": method, "road": road, "run_dir": str(run_dir),
              "resumed": state == "resume", "wall_s": round(time.monotonic() - started, 1),
              "train_wall_s": summary.get("wall_s"), "env_steps": summary.get("env_steps") or cfg.train.env_steps,
              "test": held_out(args, cfg.env),
              "eval": evals, **({"eval_by_road": by_road} if by_road is not None else {}),
              "validation": {"episode_seed": t.get("validation_seed"), "every": t["eval_every"],
                             "episodes": t["periodic_eval_episodes"], "curve": validation_curve(run_dir)},
              "command": command_line(), "git": git_revision(), "config": config}
    write_json(out_dir / f"{method}-s{seed}.json", record)
    for where, lanes in ({"": evals} if by_road is None else {f"{r}, ": e for r, e in by_road.items()}).items():
        write(f"protocol: {method} seed {seed}: {where}" + ", ".join(
            f"{lane} survival {e['survival_rate']:.1%} achievement {e['achievement_rate']:.1%}"
            for lane, e in lanes.items()))
    return record


def drive_baselines(env_cfg: EnvConfig, episodes: int, out_dir: Path,
                    filename: str = BASELINES_FILE) -> dict[str, dict]:
    """The scripted driver and the human-like stand-in on the test episodes (per initial lane), kept
    in ``filename`` (default ``baselines.json``) and read back from there while they are of the same
    episodes."""
    from laneshift.actors.envs.demonstrator import ScriptedDriver

    env = dataclasses.asdict(env_cfg)
    if not env["road"]:  # the key of the files written before env.road existed, which stay valid
        del env["road"]
    key = json.loads(json.dumps({"env": env, "episodes": episodes, "episode_seed": TEST_SEED}))
    path = out_dir / filename
    if path.is_file():
        try:
            kept = json.loads(path.read_text())
        except ValueError:
            kept = {}
        if isinstance(kept, dict) and kept.get("key") == key:
            write(f"protocol: baselines: kept from {path}")
            return kept["drivers"]
        write(f"protocol: baselines: {path} is of other test episodes; driving them again")
    label = "baseline scripted" + (f", {env_cfg.road}" if env_cfg.road else "")
    drivers = {SCRIPTED_ROW: evaluate_lanes(ScriptedDriver, env_cfg, episodes, TEST_SEED, progress=label),
               HUMAN_LIKE_ROW: human_like_lanes(env_cfg, episodes, TEST_SEED)}
    write_json(path, {"key": key, "drivers": drivers})
    return drivers


def road_baselines(env_cfg: EnvConfig, episodes: int, out_dir: Path) -> tuple[dict[str, dict], dict[str, dict]]:
    """allroads: the drivers on each road's test episodes (``baselines-<road>.json`` each), and
    pooled over the four roads as :func:`drive_baselines` returns them."""
    by_road = {road: drive_baselines(allroads.on_road(env_cfg, road), episodes, out_dir, f"baselines-{road}.json")
               for road in allroads.ALLROADS}
    pooled_drivers = {name: allroads.pooled_roads({road: by_road[road][name] for road in allroads.ALLROADS})
                      for name in (SCRIPTED_ROW, HUMAN_LIKE_ROW)}
    return pooled_drivers, by_road


def summarise(args: argparse.Namespace, road: str, runs: list[dict], drivers: dict[str, dict],
              drivers_by_road: dict[str, dict] | None = None) -> dict:
    """results.json: the protocol's numbers, in ``experiment compare``'s layout (``methods``,
    ``baselines``) plus the per-seed validation measures and the comparison with the scripted driver;
    allroads (``drivers_by_road``): the four roads pooled there, and per road in ``roads``."""
    method = args.method
    body = {"runs": runs, **lane_stats(runs)}
    per_seed = {}
    for run in runs:
        curve = run["validation"]["curve"]
        per_seed[str(run["seed"])] = {
            "reached": {f"{t:g}": time_to_threshold(curve, t) for t in THRESHOLDS},
            "largest_drop": stability_drop(curve, args.stability_target),
            "validation_evaluations": len(curve), "resumed": run.get("resumed", False)}
    scripted = drivers[SCRIPTED_ROW]
    above = {lane: {m: body[lane][m]["rate"] >= scripted[lane][f"{m}_rate"] for m in ("survival", "achievement")}
             for lane in INITIAL_LANES}
    validation = runs[0]["validation"] if runs else {}
    test = {"episode_seed": TEST_SEED, "episodes_per_lane": args.test_episodes, "max_steps": args.eval_max_steps}
    extra = {}
    if drivers_by_road is not None:
        test["roads"] = list(allroads.ALLROADS)
        extra["roads"] = allroads.road_results(runs, drivers_by_road, method, SCRIPTED_ROW)
    return {"kind": "protocol", "road": road, "scenario": args.scenario, "method": method,
            "env_steps": args.env_steps, "seeds": [r["seed"] for r in runs],
            "eval_episodes": args.test_episodes, "eval_max_steps": args.eval_max_steps,
            "test": test, **extra,
            "validation": {k: validation.get(k) for k in ("episode_seed", "every", "episodes")},
            "stability_target": args.stability_target, "thresholds": list(THRESHOLDS),
            "methods": {method: body},
            "baselines": {name: {lane: {"survival": pooled([e], "survival_rate"),
                                        "achievement": pooled([e], "achievement_rate")}
                                 for lane, e in evals.items()}
                          for name, evals in drivers.items()},
            "per_seed": per_seed, "at_or_above_scripted": above}


def render_table(results: dict) -> str:
    """table.md: the test rates per initial lane beside the baselines' (allroads: per road and initial
    lane), then per seed the time to the validation thresholds and the stability figure."""
    if "roads" in results:
        lines = allroads.render_road_table(results, (SCRIPTED_ROW, HUMAN_LIKE_ROW))
    else:
        lines = rates_table(results)
    return "\n".join(lines + validation_table(results)) + "\n"


def rates_table(results: dict) -> list[str]:
    """table.md's first part: the test rates per initial lane beside the baselines'."""
    pct = "{:.1%}".format
    method, test = results["method"], results["test"]
    runs = results["methods"][method]["runs"]
    n = len(runs)
    lines = [f"**{results['road']}, {method}**: {results['env_steps']:,} env steps per run, seeds {results['seeds']}, "
             f"the final network of each run (no checkpoint selection). Test: {test['episodes_per_lane']} greedy "
             f"episodes per initial lane (episode seeds {test['episode_seed']:,}-"
             f"{test['episode_seed'] + test['episodes_per_lane'] - 1:,}, never used for any choice), "
             f"{test['max_steps']} steps each; the baselines drive the same episodes. Learned: mean of the "
             f"per-seed rates" + (f" [95 % percentile bootstrap over seeds, {RESAMPLES:,} resamples]" if n > 1 else
                                  " (one seed: no interval)") + ", then each seed's rate.", "",
             "| initial lane | survival | achievement | survival per seed | achievement per seed "
             "| scripted driver (survival / achievement) | human-like stand-in (survival / achievement) "
             "| learned mean at/above scripted |",
             "|---|---|---|---|---|---|---|---|"]
    base = results["baselines"]
    for lane in INITIAL_LANES:
        cells = []
        for metric in ("survival", "achievement"):
            st = across_seeds(runs, lane, f"{metric}_rate")
            cells.append(pct(st["rate"]) + (f" [{pct(st['ci95'][0])}, {pct(st['ci95'][1])}]" if n > 1 else ""))
        per = [", ".join(pct(x) for x in across_seeds(runs, lane, f"{m}_rate")["per_seed"])
               for m in ("survival", "achievement")]
        drivers = [f"{pct(base[name][lane]['survival']['rate'])} / {pct(base[name][lane]['achievement']['rate'])}"
                   for name in (SCRIPTED_ROW, HUMAN_LIKE_ROW)]
        above = results["at_or_above_scripted"][lane]
        verdict = ", ".join(f"{m} {'yes' if above[m] else 'no'}" for m in ("survival", "achievement"))
        lines.append(f"| {lane} | {cells[0]} | {cells[1]} | {per[0]} | {per[1]} | {drivers[0]} | {drivers[1]} "
                     f"| {verdict} |")
    return lines


def validation_table(results: dict) -> list[str]:
    """table.md's second part: per seed the time to the validation thresholds and the stability figure."""
    pct = "{:.1%}".format
    runs = results["methods"][results["method"]]["runs"]
    val, target = results["validation"], results["stability_target"]
    if not val.get("every"):
        return ["", "Validation during training: off (--validation-every 0)."]
    lines = ["", f"Validation during training: greedy, every {val['every']:,} env steps, {val['episodes']} "
                 f"episodes (episode seeds from {val['episode_seed']:,}), on the training's initial-lane setting. "
                 f"First evaluation at or above each achievement level (env steps, wall-clock seconds since the "
                 f"run's first metrics record); largest drop of the validation achievement below its running "
                 f"best after it first reached {pct(target)}, in percentage points.", "",
             "| seed | " + " | ".join(f"{t:.0%} validation achievement" for t in results["thresholds"])
             + f" | largest drop after {pct(target)} | evaluations |",
             "|---|" + "---|" * (len(results["thresholds"]) + 2)]
    for run in runs:
        s = results["per_seed"][str(run["seed"])]
        cells = []
        for t in results["thresholds"]:
            hit = s["reached"][f"{t:g}"]
            cells.append("not reached" if hit is None else f"{hit['env_steps']:,} steps"
                         + (f", {hit['elapsed_s']:,.0f} s" if hit.get("elapsed_s") is not None else ""))
        drop = "not reached" if s["largest_drop"] is None else f"{100 * s['largest_drop']:.1f} points"
        note = " (resumed: its seconds include the pause)" if s.get("resumed") else ""
        lines.append(f"| {run['seed']}{note} | " + " | ".join(cells) + f" | {drop} | {s['validation_evaluations']} |")
    return lines


def plot_validation(results: dict, out_dir: Path) -> Path | None:
    """``curves_validation.png``: validation survival and achievement against env steps, the mean
    over seeds with a 95 % bootstrap band over seeds (``plots.plot_eval_curves``); None when
    no seed has two validation evaluations."""
    method = results["method"]
    runs = results["methods"][method]["runs"]
    return plot_eval_curves({**results, "scenario": results["road"]}, out_dir,
                            {f"{method}-s{r['seed']}": {"evals": r["validation"]["curve"]} for r in runs},
                            filename="curves_validation.png",
                            what=f"validation, episode seeds {results['validation']['episode_seed']:,}+")


def published_rates(checkpoint: Path, env: dict, test: dict, evals: dict[str, dict]) -> dict[str, dict]:
    """A published JSON's test rates per initial lane, each with the ``laneshift eval`` command that
    reproduces it."""
    return {lane: {"survival_rate": e["survival_rate"], "achievement_rate": e["achievement_rate"],
                   "episodes": e["episodes"], "survival_ci95": e.get("survival_ci95"),
                   "achievement_ci95": e.get("achievement_ci95"),
                   "command": eval_command(checkpoint, env, test["episodes_per_lane"], test["max_steps"], lane)}
            for lane, e in evals.items()}


def publish(results: dict, dest: Path, road: str) -> list[Path]:
    """Each seed's final network as ``dest/<road>-<method>-seed<N>-final.safetensors`` with its
    provenance and test table beside it (``.json``); allroads: the four roads pooled in ``lanes``
    (no one command gives them) and per road in ``roads``, with each road's ``laneshift eval``
    commands."""
    dest.mkdir(parents=True, exist_ok=True)
    method, written = results["method"], []
    for run in results["methods"][method]["runs"]:
        seed = run["seed"]
        final = Path(run["run_dir"]) / "checkpoints" / "final.safetensors"
        if not final.is_file():
            write(f"protocol: publish: seed {seed}: {final} is gone; not published")
            continue
        stem = f"{road}-{method}-seed{seed}-final"
        checkpoint = dest / f"{stem}.safetensors"
        shutil.copyfile(final, checkpoint)
        test = run["test"]
        env = run["config"]["env"]
        by_road = run.get("eval_by_road")
        if by_road is None:
            lanes = published_rates(checkpoint, env, test, run["eval"])
            roads = {}
        else:
            roads = {"roads": {r: published_rates(checkpoint, {**env, "road": r}, test, e) for r, e in by_road.items()}}
            lanes = {lane: {k: e.get(k) for k in ("survival_rate", "achievement_rate", "episodes", "survival_ci95",
                                                  "achievement_ci95")} | {"pooled_over": list(by_road)}
                     for lane, e in run["eval"].items()}
        doc = {"checkpoint": checkpoint.name, "road": road, "method": method, "seed": seed,
               "command": command_line(), "cwd": os.getcwd(), "git": git_revision(),
               "trained_by": {"command": run.get("command"), "git": run.get("git")},
               "env_steps": run["env_steps"], "run_dir": run["run_dir"],
               "test": {"episode_seed": test["episode_seed"], "episodes_per_lane": test["episodes_per_lane"],
                        "max_steps": test["max_steps"], "lanes": lanes, **roads},
               "validation": run["validation"], "config": run["config"]}
        write_json(dest / f"{stem}.json", doc)
        written += [checkpoint, dest / f"{stem}.json"]
        write(f"protocol: published {checkpoint} and {stem}.json")
    return written


def run_protocol(args: argparse.Namespace) -> dict:
    out_dir, road, configs, states = plan(args)
    out_dir.mkdir(parents=True, exist_ok=True)
    method = args.method
    runs = []
    with progress(total=len(configs), desc=f"protocol {road} {method}", unit="seed") as bar:
        for seed, cfg in configs.items():
            record = out_dir / f"{method}-s{seed}.json"
            state = states[seed]
            if state == "done":
                write(f"protocol: {method} seed {seed}: done ({record}), skipped")
                runs.append(json.loads(record.read_text()))
            else:
                if state == "resume":
                    write(f"protocol: {method} seed {seed}: continuing the unfinished run in {cfg.train.run_dir}")
                elif state == "trained":
                    write(f"protocol: {method} seed {seed}: the run in {cfg.train.run_dir} finished; "
                          f"evaluating its final network")
                runs.append(run_seed(cfg, state, args, out_dir, road))
            bar.update()
    env_cfg = dataclasses.replace(next(iter(configs.values())).env, max_steps=args.eval_max_steps)
    # Where the drivers' rows are kept: this study's dir, or one that several studies of the same
    # test episodes share (`experiment paper`'s modes), so the drivers drive them once.
    baselines_dir = Path(getattr(args, "baselines_dir", None) or out_dir)
    baselines_dir.mkdir(parents=True, exist_ok=True)
    if env_cfg.is_allroads:
        drivers, drivers_by_road = road_baselines(env_cfg, args.test_episodes, baselines_dir)
        results = summarise(args, road, runs, drivers, drivers_by_road)
    else:
        drivers = drive_baselines(env_cfg, args.test_episodes, baselines_dir)
        results = summarise(args, road, runs, drivers)
    results["command"] = command_line()
    write_json(out_dir / "results.json", results)
    table = render_table(results)
    (out_dir / "table.md").write_text(table)
    if plot_validation(results, out_dir) is None:
        write("protocol: curves_validation.png not drawn: no seed has two validation evaluations")
    if args.publish:
        publish(results, Path(args.publish), road)
    print(table)
    return results


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("protocol", help="the whole evaluation protocol for one method on one road (or one "
                                               "network for all four): train seeds, test the final networks, "
                                               "baselines, table, publish")
    p.add_argument("--scenario", default="straight", choices=SCENARIO_CHOICES,
                   help="the road; allroads: one network for the four roads, tested on each")
    p.add_argument("--method", default="dqfd-bc", help=f"one of {', '.join(METHODS)}")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated training seeds: one run each")
    p.add_argument("--env-steps", type=positive_int, default=600_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--test-episodes", type=positive_int, default=200,
                   help=f"test episodes per initial-lane setting (episode seeds from {TEST_SEED:,})")
    p.add_argument("--eval-max-steps", type=positive_int, default=300, help="test episode length (paper: 300)")
    p.add_argument("--validation-every", type=non_negative_int, default=None, metavar="ENV_STEPS",
                   help="env steps between greedy validation evaluations during training (default: "
                        f"--env-steps // 10; 0 = off; episode seeds from {VALIDATION_SEED:,})")
    p.add_argument("--validation-episodes", type=positive_int, default=20, help="episodes per validation evaluation")
    p.add_argument("--stability-target", type=fraction, default=0.93,
                   help="validation achievement after whose first crossing the largest drop is measured")
    p.add_argument("--out", metavar="DIR", help="where the runs, results.json, table.md and the figure go "
                                                "(default: runs/protocol/<road>-<method>)")
    p.add_argument("--publish", metavar="DIR", help="copy each seed's final network with its provenance and test "
                                                    "table here (e.g. results/checkpoints)")
    p.add_argument("--road", help="the road's name in the published files (default: the scenario, with "
                                  "-policytraffic when env.policy_vehicles > 0)")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_protocol(a), 0)[1])
