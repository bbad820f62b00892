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

``--final-validation-episodes N`` also evaluates each final network, and the drivers, on N
validation episodes per initial-lane setting (seeds from 200,000, or from ``--final-validation-seed``; allroads:
on each road): the numbers to choose between recipes or settings on, so that the test episodes serve no choice.
The same command again with it adds them to seeds already done (again with another seed: replaces them).
``--final-validation-seed S`` (at least 200,000) judges a probe on validation episodes that no earlier choice
was made on: the episodes an earlier study chose on flatter what it chose. ``--hold-test`` (a probe): each seed is
trained and its final network driven on those validation episodes only; the test episodes are not
driven, so no test rate is printed or written while the choice is open; table.md and results.json hold
the validation rates (``test_held``). The same command without ``--hold-test`` then drives the test
episodes of the seeds validated before, training nothing.

``--scenario allroads`` trains one network for the four roads and tests it on each road's own test
episodes (the single-road protocol's, the road pinned with ``env.road``), the drivers on the same
episodes, one table row per road and initial lane (``laneshift.tools.studies.allroads``); its published
JSON holds the per-road ``laneshift eval`` commands.

The pieces: this module (the command: the plan, each seed's run and test), ``protocol_results``
(the drivers' rows, results.json, table.md), ``protocol_validation`` (the validation curve's
measures, table and figure), ``protocol_publish`` (the published networks) and ``provenance``.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import yaml
from tqdm import tqdm

from laneshift.checkpoints import run_checkpoint
from laneshift.config import METHODS, ConfigError, EnvConfig, RunConfig, load_run_config, method_settings
from laneshift.progress import progress, write
from laneshift.tools.argtypes import add_set_arg, fraction, non_negative_int, parse_set, positive_int, seed_list
from laneshift.tools.studies import allroads
from laneshift.tools.studies.evaluate import Policy, evaluate_lanes, load_greedy_policy
from laneshift.tools.studies.protocol_publish import publish_run
from laneshift.tools.studies.protocol_results import (TEST_SEED, drivers_on, final_validation_results,
                                                      held_test_summary, render_table, summarise)
from laneshift.tools.studies.protocol_validation import VALIDATION_SEED, plot_validation, validation_curve
from laneshift.tools.studies.provenance import command_line, git_revision, write_json
from laneshift.tools.studies.runs import method_config, metrics_records, train_logged

SCENARIOS = ("straight", "merge", "curve", "roundabout")
#: ``--scenario``'s choices: a road, or one network for all four.
SCENARIO_CHOICES = (*SCENARIOS, "allroads")


def road_name(env: EnvConfig, scenario: str) -> str:
    """The published files' road: the scenario, ``-policytraffic`` when other vehicles drive with
    the agent's policy (``env.policy_vehicles``)."""
    return scenario + ("-policytraffic" if env.policy_vehicles > 0 else "")


def held_out(args: argparse.Namespace, env: EnvConfig) -> dict:
    """A seed record's ``test``: the test episodes (allroads: on each of these roads)."""
    test = {"episode_seed": TEST_SEED, "episodes_per_lane": args.test_episodes, "max_steps": args.eval_max_steps}
    return {**test, "roads": list(allroads.ALLROADS)} if env.is_allroads else test


def seed_state(run_dir: Path, record: Path) -> str:
    """``done`` (its json exists), ``validated`` (its json exists, its test episodes held: not driven
    yet), ``trained`` (the run finished, not evaluated yet), ``resume`` (a run stopped unfinished) or
    ``new``."""
    if record.is_file():
        try:
            held = json.loads(record.read_text()).get("test_held", False)
        except (OSError, ValueError, AttributeError):
            held = False  # check_same_protocol says what is wrong with it
        return "validated" if held else "done"
    if not (run_dir / "config.yaml").is_file():
        return "new"
    try:
        ended = json.loads((run_dir / "summary.json").read_text()).get("ended_by")
    except (OSError, ValueError, AttributeError):
        ended = None
    return "trained" if ended == "done" and run_checkpoint(run_dir).is_file() else "resume"


def check_same_protocol(seed: int, record: Path, test: dict, env_steps: int) -> None:
    """A finished seed joins a study only if it is of the same protocol: its record's test episodes
    and budget are this command's (ConfigError naming what differs otherwise)."""
    try:
        kept = json.loads(record.read_text())
        differ = {"test": (kept["test"], test), "env_steps": (kept["config"]["train"]["env_steps"], env_steps)}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"seed {seed}: {record} is not readable ({exc}); remove it to evaluate the "
                          f"seed again") from None
    differ = {k: v for k, v in differ.items() if v[0] != v[1]}
    if differ:
        raise ConfigError(f"seed {seed}: {record} is of another protocol ("
                          + ", ".join(f"{k} {v[0]} there, {v[1]} now" for k, v in differ.items())
                          + "); choose another --out, or remove it to evaluate the seed again")


def checked_seeds(args: argparse.Namespace) -> list[int]:
    """``--seeds`` as a list, once ``--method`` is known to name a method and no seed is named twice
    (ConfigError otherwise)."""
    method_settings(args.method, "--method")
    seeds = seed_list(args.seeds)
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"--seeds: a seed is named twice in {args.seeds!r}")
    return seeds


def plan(args: argparse.Namespace) -> tuple[Path, str, dict[int, RunConfig], dict[int, str]]:
    """(out dir, road, each seed's config, each seed's state): every config is built (and a bad
    method, seed or --set refused) before the first run starts. A seed whose run stopped unfinished
    gets its saved config with this command's settings on top (as ``laneshift train --resume``)."""
    user = parse_set(args.set)
    seeds = checked_seeds(args)
    if args.hold_test and not args.final_validation_episodes:
        raise ConfigError("--hold-test: the seeds are then judged on validation episodes only; give "
                          "--final-validation-episodes N (e.g. 200)")
    if args.hold_test and args.publish:
        raise ConfigError("--hold-test: a network is published with its test table; publish with the command "
                          "that drives the test episodes (the same without --hold-test)")
    if args.final_validation_seed < VALIDATION_SEED:
        raise ConfigError(f"--final-validation-seed: validation episodes are seeded from {VALIDATION_SEED:,} up "
                          f"(below are the test episodes'), got {args.final_validation_seed:,}")
    if TEST_SEED + args.test_episodes > VALIDATION_SEED:
        raise ConfigError(f"--test-episodes: at most {VALIDATION_SEED - TEST_SEED:,} (the test episodes' seeds "
                          f"from {TEST_SEED:,} would reach the validation episodes' from {VALIDATION_SEED:,})")
    if args.road is not None and (not args.road.strip() or "/" in args.road or args.road != args.road.strip()):
        raise ConfigError(f"--road: a name for file names (no '/', no surrounding spaces), got {args.road!r}")
    every = args.env_steps // 10 if args.validation_every is None else args.validation_every
    shortcuts = {"env.scenario": args.scenario, "actor.workers": args.workers, **user}
    # Checked with the method's settings under the user's: a --set that needs one of them (a shield
    # figure needs the method's env.shield) is valid here as it is in each seed's config.
    base = load_run_config(args.config, {**method_settings(args.method, "--method"), **shortcuts})
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
        if states[seed] in ("done", "validated"):
            check_same_protocol(seed, record, test, args.env_steps)
        seed_base = base
        if states[seed] == "resume":
            try:
                seed_base = load_run_config(run_dir / "config.yaml", shortcuts)
            except ConfigError as exc:
                raise ConfigError(f"seed {seed}: the unfinished run in {run_dir}: {exc}") from None
        configs[seed] = config(seed_base, seed, run_dir)
    return out_dir, road, configs, states


def train_seed(cfg: RunConfig, state: str, out_dir: Path, method: str) -> None:
    """Train a ``new`` seed's run, or continue an unfinished one (``resume``), its log in
    ``out_dir/<method>-s<seed>.log``; a ``trained`` seed has nothing left to train."""
    if state not in ("new", "resume"):
        return
    seed = cfg.train.seed
    try:
        train_logged(cfg, out_dir / f"{method}-s{seed}.log", label=f"train {method} seed {seed}",
                     resume=state == "resume")
    except RuntimeError as exc:  # failed, or stopped (Ctrl-C, SIGTERM) with its checkpoints
        raise SystemExit(f"seed {seed}: {exc}; the same command again continues it") from None


def run_seed(cfg: RunConfig, state: str, args: argparse.Namespace, out_dir: Path, road: str) -> dict:
    """Train (or continue) one seed's run, evaluate its final network on the validation episodes
    (``--final-validation-episodes``) and, unless ``--hold-test``, on the test episodes; write and
    return its ``<method>-s<seed>.json``."""
    seed, method = cfg.train.seed, args.method
    run_dir = Path(cfg.train.run_dir)
    started = time.monotonic()
    train_seed(cfg, state, out_dir, method)
    greedy = load_greedy_policy(run_checkpoint(run_dir))
    test_env = dataclasses.replace(cfg.env, max_steps=args.eval_max_steps)
    final_validation = validate_final(greedy, test_env, args.final_validation_episodes, args.final_validation_seed,
                                      f"validate {method} seed {seed}")
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
              "validation": {"episode_seed": t.get("validation_seed"), "every": t["eval_every"],
                             "episodes": t["periodic_eval_episodes"], "curve": validation_curve(run_dir)},
              **({"final_validation": final_validation} if final_validation else {}),
              "command": command_line(), "git": git_revision(), "config": config}
    if args.hold_test:
        record["test_held"] = True
        write_json(out_dir / f"{method}-s{seed}.json", record)
        say_rates(f"{method} seed {seed} (validation episodes; test held)", final_validation)
        return record
    return with_test_rates(record, greedy, test_env, args, out_dir)


def with_test_rates(record: dict, greedy: Policy, test_env: EnvConfig, args: argparse.Namespace,
                    out_dir: Path) -> dict:
    """A seed's record with its final network's rates on the test episodes (``eval``; allroads
    ``eval_by_road`` too), ``test_held`` gone and ``command`` the one that drove them, written as
    ``<method>-s<seed>.json`` and returned."""
    seed, method = record["seed"], record["method"]
    tested = evaluate_final(greedy, test_env, args.test_episodes, TEST_SEED, f"test {method} seed {seed}")
    record = {**{k: v for k, v in record.items() if k != "test_held"}, **tested, "command": command_line()}
    write_json(out_dir / f"{method}-s{seed}.json", record)
    say_rates(f"{method} seed {seed}", tested)
    return record


def drive_held_test(record_path: Path, cfg: RunConfig, args: argparse.Namespace, out_dir: Path) -> dict:
    """A seed validated before with its test held: its final network on the test episodes now."""
    record = add_final_validation(record_path, cfg, args)
    greedy = load_greedy_policy(run_checkpoint(cfg.train.run_dir))
    test_env = dataclasses.replace(cfg.env, max_steps=args.eval_max_steps)
    return with_test_rates(record, greedy, test_env, args, out_dir)


def say_rates(what: str, evaluated: dict) -> None:
    """One line per evaluation of a final network (allroads: its roads on one line)."""
    evals, by_road = evaluated["eval"], evaluated.get("eval_by_road")
    for where, lanes in ({"": evals} if by_road is None else {f"{r}, ": e for r, e in by_road.items()}).items():
        write(f"protocol: {what}: {where}" + ", ".join(
            f"{lane} survival {e['survival_rate']:.1%} achievement {e['achievement_rate']:.1%}"
            for lane, e in lanes.items()))


def evaluate_final(greedy: Policy, env_cfg: EnvConfig, episodes: int, episode_seed: int, label: str) -> dict:
    """A final network on ``episodes`` episodes per initial lane from ``episode_seed``: ``eval``; for
    allroads each road's own episodes (``eval_by_road``), pooled in ``eval``."""
    if env_cfg.is_allroads:
        by_road = allroads.evaluate_roads(lambda env: greedy, env_cfg, episodes, episode_seed, progress=label)
        return {"eval": allroads.pooled_roads(by_road), "eval_by_road": by_road}
    return {"eval": evaluate_lanes(lambda env: greedy, env_cfg, episodes, episode_seed, progress=label)}


def validate_final(greedy: Policy, env_cfg: EnvConfig, episodes: int, episode_seed: int, label: str) -> dict | None:
    """A final network on ``episodes`` validation episodes per initial lane from ``episode_seed``
    (allroads: on each road too, as its test); None for 0 episodes."""
    if not episodes:
        return None
    return {"episode_seed": episode_seed, "episodes_per_lane": episodes, "max_steps": env_cfg.max_steps,
            **evaluate_final(greedy, env_cfg, episodes, episode_seed, label)}


def add_final_validation(record_path: Path, cfg: RunConfig, args: argparse.Namespace) -> dict:
    """A done seed's record, with its final network's validation rates added (and written) where this
    command asks for them and the record has none of those episodes (that many, from that seed)."""
    record = json.loads(record_path.read_text())
    episodes, first = args.final_validation_episodes, args.final_validation_seed
    kept = record.get("final_validation") or {}
    if not episodes or (kept.get("episodes_per_lane"), kept.get("episode_seed")) == (episodes, first):
        return record
    final = run_checkpoint(cfg.train.run_dir)
    if not final.is_file():
        raise ConfigError(f"seed {cfg.train.seed}: --final-validation-episodes needs the run's final network, and "
                          f"{final} is not there")
    greedy = load_greedy_policy(final)
    test_env = dataclasses.replace(cfg.env, max_steps=args.eval_max_steps)
    record["final_validation"] = validate_final(greedy, test_env, episodes, first,
                                                f"validate {args.method} seed {cfg.train.seed}")
    write_json(record_path, record)
    return record


def seeds_progress(states: dict[int, str], desc: str, finished: tuple[str, ...] = ("done",),
                   started: dict[int, float] | None = None) -> tqdm:
    """A study's bar over its seeds. The seeds finished before this command (``finished``: their
    states) are its start (tqdm's ``initial``), not seeds done now in no time, and so is the share
    of its budget a stopped run made before (``started``, by seed: :func:`started_shares`): call
    ``update(1 - started.get(seed, 0))`` only for the others, so the rate and the time left count
    only what this command trains or evaluates."""
    initial = sum(state in finished for state in states.values()) + sum((started or {}).values())
    return progress(total=len(states), initial=initial, desc=desc, unit="seed")


def started_shares(configs: dict[int, RunConfig], states: dict[int, str]) -> dict[int, float]:
    """Each stopped run's (state ``resume``) share of its env-step budget made before it stopped:
    the env steps of its last learner record in metrics.jsonl (0 where it had none, as in
    pre-training)."""
    shares = {}
    for seed, cfg in configs.items():
        path = Path(cfg.train.run_dir) / "metrics.jsonl"
        if states[seed] != "resume" or not path.is_file():
            continue
        steps = [rec["env_steps"] for rec in metrics_records(path)
                 if rec.get("kind") == "learner" and isinstance(rec.get("env_steps"), int)]
        shares[seed] = min((steps[-1] if steps else 0) / cfg.train.env_steps, 1.0)
    return shares


def run_protocol(args: argparse.Namespace) -> dict:
    out_dir, road, configs, states = plan(args)
    out_dir.mkdir(parents=True, exist_ok=True)
    method = args.method
    runs = []
    # With the test held, a seed validated before is as finished as a done one; without, its test is left.
    finished = ("done", "validated") if args.hold_test else ("done",)
    started = started_shares(configs, states)
    with seeds_progress(states, f"protocol {road} {method}", finished, started) as bar:
        for seed, cfg in configs.items():
            record = out_dir / f"{method}-s{seed}.json"
            state = states[seed]
            if state in finished:
                write(f"protocol: {method} seed {seed}: {state} ({record}), skipped")
                runs.append(add_final_validation(record, cfg, args))
            elif state == "validated":
                write(f"protocol: {method} seed {seed}: validated before, its test held; driving its test episodes")
                runs.append(drive_held_test(record, cfg, args, out_dir))
            else:
                if state == "resume":
                    write(f"protocol: {method} seed {seed}: continuing the unfinished run in {cfg.train.run_dir}")
                elif state == "trained":
                    write(f"protocol: {method} seed {seed}: the run in {cfg.train.run_dir} finished; "
                          f"evaluating its final network")
                runs.append(run_seed(cfg, state, args, out_dir, road))
            if args.publish:  # each seed as it is done: a later seed's run may be stopped before the study's end
                publish_run(runs[-1], Path(args.publish), road, method)
            if state not in finished:
                bar.update(1 - started.get(seed, 0.0))
    env_cfg = dataclasses.replace(next(iter(configs.values())).env, max_steps=args.eval_max_steps)
    # Where the drivers' rows are kept: this study's dir, or one that several studies of the same
    # test episodes share (`experiment paper`'s modes), so the drivers drive them once.
    baselines_dir = Path(getattr(args, "baselines_dir", None) or out_dir)
    baselines_dir.mkdir(parents=True, exist_ok=True)
    if args.final_validation_episodes:  # the drivers on the same validation episodes
        first = args.final_validation_seed  # a file per first seed: each set of episodes kept beside the others
        validation_drivers = drivers_on(env_cfg, args.final_validation_episodes, baselines_dir, first,
                                        "baselines-validation" + ("" if first == VALIDATION_SEED else f"-{first}"))
    if args.hold_test:  # the validation rates where the test's would be; no test episode driven
        results = held_test_summary(args, road, runs, *validation_drivers)
    else:
        results = summarise(args, road, runs, *drivers_on(env_cfg, args.test_episodes, baselines_dir))
        if args.final_validation_episodes:
            results["final_validation"] = final_validation_results(args, runs, *validation_drivers,
                                                                   args.final_validation_seed)
    results["command"] = command_line()
    write_json(out_dir / "results.json", results)
    table = render_table(results)
    (out_dir / "table.md").write_text(table)
    if plot_validation(results, out_dir) is None:
        write("protocol: curves_validation.png not drawn: no seed has two validation evaluations")
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
    p.add_argument("--final-validation-episodes", type=non_negative_int, default=0, metavar="N",
                   help=f"also evaluate each final network and the drivers on N validation episodes per initial "
                        f"lane (episode seeds from {VALIDATION_SEED:,}): the numbers to choose between recipes on "
                        f"(0 = off; again on a finished study: adds them)")
    p.add_argument("--final-validation-seed", type=non_negative_int, default=VALIDATION_SEED, metavar="S",
                   help=f"the first episode seed of --final-validation-episodes (default {VALIDATION_SEED:,}; at "
                        f"least that): fresh validation episodes for a probe, that no earlier choice was made on")
    p.add_argument("--hold-test", action="store_true",
                   help="a probe: train and evaluate the final networks on the validation episodes only (needs "
                        "--final-validation-episodes); the test episodes are not driven until the same command "
                        "runs without --hold-test")
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
