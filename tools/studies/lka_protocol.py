"""``laneshift experiment lka``: the LKA protocol (the MATLAB lane-keeping example) in one command.

Per training seed (default 0, 1, 2) one real local run on the LKA plant; then the run's FINAL
network (no checkpoint is chosen) is evaluated greedily on the test episodes (episode seeds from
100,000, never used for any choice; ``--test-episodes``) and with MATLAB's response test (from
e1 = -0.4 m, e2 = 0.2 rad: when the car is centred, |e1| <= 5 cm, and how much the steering still
moves). The LQR expert (``LKAExpert``) drives the same episodes and the same response test. The
mean return over seeds comes with a 95 % percentile bootstrap interval over seeds.

    laneshift experiment lka --method matlab-dqn --seeds 0,1,2 --env-steps 20000 --publish results/checkpoints

Resumable as ``experiment protocol`` is: a seed whose ``<method>-s<seed>.json`` exists is skipped,
an unfinished run is continued, a finished one not yet evaluated is evaluated. Writes to ``--out``
(default ``runs/protocol/lka-<method>``): each seed's run dir, training log, ``<method>-s<seed>.json``
and response figure, ``results.json`` and ``table.md``. ``--publish DIR``: each seed's final network
as ``DIR/lka-<method>-seed<N>-final.safetensors`` with a ``.json`` beside it (command line, git
revision, resolved config, the test table and the ``laneshift eval`` command that reproduces it).

The lane-change protocol (``protocol``) measures survival and achievement per initial lane; the
plant has neither lanes to change nor a target, so its numbers here are MATLAB's: the return, the
episodes that stay on the road, the time to centre and the steering's settling.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import shlex
import time
from pathlib import Path

import yaml

from laneshift.checkpoints import run_checkpoint
from laneshift.config import METHODS, ConfigError, EnvConfig, RunConfig, load_run_config
from laneshift.progress import write
from laneshift.tools.argtypes import add_set_arg, parse_set, positive_int
from laneshift.tools.studies.evaluate import evaluate_policy, load_greedy_policy, lka_response, plot_lka_response
from laneshift.tools.studies.protocol import (check_same_protocol, checked_seeds, seed_state, seeds_progress,
                                             started_shares, train_seed)
from laneshift.tools.studies.protocol_publish import publish_final
from laneshift.tools.studies.protocol_results import TEST_SEED
from laneshift.tools.studies.provenance import command_line, git_revision, write_json
from laneshift.tools.studies.runs import method_config
from laneshift.tools.studies.stats import bootstrap_ci

ROAD = "lka"
EXPERT_ROW = "LQR expert"
#: What a seed's record keeps of the response test (its trace goes to the figure only).
RESPONSE_KEYS = ("e1_0", "e2_0", "return", "left_lane", "centred_after_s", "steering_settled_after_s",
                 "steering_chatter_deg", "final_e1", "final_e2")


def plan(args: argparse.Namespace) -> tuple[Path, dict[int, RunConfig], dict[int, str]]:
    """(out dir, each seed's config, each seed's state); every config is built, and a bad method,
    seed or --set refused, before the first run starts."""
    user = parse_set(args.set)
    seeds = checked_seeds(args)
    base = load_run_config(args.config, {"env.scenario": ROAD, "actor.workers": args.workers, **user})
    if base.env.scenario != ROAD:
        raise ConfigError(f"env.scenario: the LKA protocol runs on the lka plant, not {base.env.scenario!r}")
    out_dir = Path(args.out or f"runs/protocol/{ROAD}-{args.method}").resolve()
    configs, states = {}, {}
    for seed in seeds:
        run_dir = out_dir / f"{args.method}-s{seed}"
        record = out_dir / f"{args.method}-s{seed}.json"
        states[seed] = seed_state(run_dir, record)
        if states[seed] == "done":
            check_same_protocol(seed, record, test_section(args), args.env_steps)
        seed_base = load_run_config(run_dir / "config.yaml", {"env.scenario": ROAD}) if states[seed] == "resume" else base
        configs[seed] = method_config(seed_base, args.method, seed, run_dir, args.env_steps, user)
    return out_dir, configs, states


def test_section(args: argparse.Namespace) -> dict:
    """A seed record's ``test``: the test episodes."""
    return {"episode_seed": TEST_SEED, "episodes": args.test_episodes}


def test_drive(make_policy, env_cfg: EnvConfig, episodes: int, label: str, png: Path) -> dict:
    """A policy on the test episodes and the response test (its figure written to ``png``)."""
    evals = evaluate_policy(make_policy, env_cfg, episodes, TEST_SEED, progress=label)
    response = lka_response(make_policy)
    plot_lka_response(response, png)
    return {"eval": evals, "response": {k: response[k] for k in RESPONSE_KEYS} | {"png": png.name}}


def run_seed(cfg: RunConfig, state: str, args: argparse.Namespace, out_dir: Path) -> dict:
    """Train (or continue) one seed's run, test its final network, write and return its record."""
    seed, method = cfg.train.seed, args.method
    run_dir = Path(cfg.train.run_dir)
    started = time.monotonic()
    train_seed(cfg, state, out_dir, method)
    greedy = load_greedy_policy(run_checkpoint(run_dir))
    tested = test_drive(lambda env: greedy, cfg.env, args.test_episodes, f"test {method} seed {seed}",
                        out_dir / f"{method}-s{seed}.lka_response.png")
    try:
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, ValueError):
        summary = {}
    record = {"seed": seed, "method": method, "road": ROAD, "run_dir": str(run_dir), "resumed": state == "resume",
              "wall_s": round(time.monotonic() - started, 1), "train_wall_s": summary.get("wall_s"),
              "env_steps": summary.get("env_steps") or cfg.train.env_steps,
              "test": test_section(args), **tested,
              "command": command_line(), "git": git_revision(),
              "config": yaml.safe_load((run_dir / "config.yaml").read_text())}
    write_json(out_dir / f"{method}-s{seed}.json", record)
    r = tested["response"]
    write(f"lka: {method} seed {seed}: return {tested['eval']['return_mean']:.2f}, survival "
          f"{tested['eval']['survival_rate']:.0%}, centred after {_seconds(r['centred_after_s'])}, "
          f"steering peak to peak {r['steering_chatter_deg']:.1f} deg")
    return record


def expert_row(env_cfg: EnvConfig, episodes: int, out_dir: Path) -> dict:
    """The LQR expert on the same test episodes and response test."""
    from laneshift.actors.envs.demonstrator import LKAExpert

    return test_drive(LKAExpert, env_cfg, episodes, "baseline LQR expert", out_dir / "expert.lka_response.png")


def summarise(args: argparse.Namespace, runs: list[dict], expert: dict) -> dict:
    returns = [r["eval"]["return_mean"] for r in runs]
    lo, hi = bootstrap_ci(returns)
    return {"kind": "lka-protocol", "road": ROAD, "method": args.method, "env_steps": args.env_steps,
            "seeds": [r["seed"] for r in runs], "test": {"episode_seed": TEST_SEED, "episodes": args.test_episodes},
            "return_mean": sum(returns) / len(returns), "return_ci95": [lo, hi],
            "survival_rate": sum(r["eval"]["survival_rate"] for r in runs) / len(runs),
            "runs": runs, "expert": expert, "command": command_line()}


def _seconds(value: float | None) -> str:
    return "never" if value is None else f"{value:.1f} s"


def render_table(results: dict) -> str:
    t = results["test"]
    lines = [f"**lka, {results['method']}**: {results['env_steps']:,} env steps per run, seeds {results['seeds']}, "
             f"the final network of each run (no checkpoint selection). Test: {t['episodes']} greedy episodes "
             f"(episode seeds {t['episode_seed']:,}-{t['episode_seed'] + t['episodes'] - 1:,}, never used for "
             f"any choice); the response test drives from e1 = -0.4 m, e2 = 0.2 rad (MATLAB: centred within "
             f"about 2.5 s, steering settled after about 2 s). Mean return over seeds "
             f"{results['return_mean']:.2f} [{results['return_ci95'][0]:.2f}, {results['return_ci95'][1]:.2f}] "
             f"(95 % percentile bootstrap over seeds).", "",
             "| policy | return (mean +- std over episodes) | survival | centred (\\|e1\\| <= 5 cm) after "
             "| steering settled (within 1 deg) after | steering peak to peak, last 5 s | training |",
             "|---|---|---|---|---|---|---|"]

    def row(name: str, e: dict, r: dict, train: str) -> str:
        return (f"| {name} | {e['return_mean']:.2f} +- {e['return_std']:.2f} | {e['survival_rate']:.0%} | "
                f"{_seconds(r['centred_after_s'])} | {_seconds(r['steering_settled_after_s'])} | "
                f"{r['steering_chatter_deg']:.1f} deg | {train} |")

    for run in results["runs"]:
        train = f"{run['train_wall_s']:.0f} s" if run.get("train_wall_s") is not None else "-"
        lines.append(row(f"seed {run['seed']}", run["eval"], run["response"], train))
    lines.append(row(EXPERT_ROW, results["expert"]["eval"], results["expert"]["response"], "-"))
    return "\n".join(lines) + "\n"


def eval_command(checkpoint: Path, episodes: int) -> str:
    return shlex.join(["laneshift", "eval", "--checkpoint", str(checkpoint), "--scenario", ROAD,
                       "--episodes", str(episodes), "--seed", str(TEST_SEED)])


def publish(results: dict, dest: Path) -> list[Path]:
    """Each seed's final network as ``dest/lka-<method>-seed<N>-final.safetensors`` with its
    provenance and test table beside it (``.json``)."""
    dest.mkdir(parents=True, exist_ok=True)
    written = []
    for run in results["runs"]:
        e = run["eval"]
        written += publish_final(run, dest, ROAD, results["method"], "lka", lambda checkpoint, e=e, run=run: {
            "test": {"episode_seed": TEST_SEED, "episodes": e["episodes"], "return_mean": e["return_mean"],
                     "return_std": e["return_std"], "survival_rate": e["survival_rate"],
                     "response": run["response"], "command": eval_command(checkpoint, e["episodes"])}})
    return written


def run_lka(args: argparse.Namespace) -> dict:
    out_dir, configs, states = plan(args)
    out_dir.mkdir(parents=True, exist_ok=True)
    runs = []
    started = started_shares(configs, states)
    with seeds_progress(states, f"lka protocol {args.method}", started=started) as bar:
        for seed, cfg in configs.items():
            record = out_dir / f"{args.method}-s{seed}.json"
            if states[seed] == "done":
                write(f"lka: {args.method} seed {seed}: done ({record}), skipped")
                runs.append(json.loads(record.read_text()))
            else:
                runs.append(run_seed(cfg, states[seed], args, out_dir))
                bar.update(1 - started.get(seed, 0.0))
    expert = expert_row(next(iter(configs.values())).env, args.test_episodes, out_dir)
    results = summarise(args, runs, expert)
    write_json(out_dir / "results.json", results)
    table = render_table(results)
    (out_dir / "table.md").write_text(table)
    if args.publish:
        publish(results, Path(args.publish))
    print(table)
    return results


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("lka", help="the LKA protocol (MATLAB's lane-keeping example): train seeds, test the "
                                          "final networks and the response, the LQR expert beside them, publish")
    p.add_argument("--method", default="matlab-dqn", help=f"one of {', '.join(METHODS)}")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated training seeds: one run each")
    p.add_argument("--env-steps", type=positive_int, default=20_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--test-episodes", type=positive_int, default=200,
                   help=f"test episodes (episode seeds from {TEST_SEED:,})")
    p.add_argument("--out", metavar="DIR", help="where the runs, results.json and table.md go "
                                                "(default: runs/protocol/lka-<method>)")
    p.add_argument("--publish", metavar="DIR", help="copy each seed's final network with its provenance and test "
                                                    "table here (e.g. results/checkpoints)")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_lka(a), 0)[1])
