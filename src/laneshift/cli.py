"""The ``laneshift`` command. ``laneshift --help`` lists the subcommands.

    laneshift train --local --workers 2 --scenario straight --mode rehearsal --env-steps 20000 --run-dir runs/demo
    laneshift replay-server --config runs/demo/config.yaml
    laneshift learner --config runs/demo/config.yaml
    laneshift demos generate --scenario straight --episodes 50 --out demos/straight
    laneshift eval --checkpoint runs/demo/checkpoints/final.safetensors --scenario straight --episodes 200
    laneshift replay inspect --router tcp/127.0.0.1:7447 --run-id run
    laneshift bench env
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from .config import ConfigError, RunConfig, load_run_config


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="YAML/TOML/JSON file with sections env, actor, replay, learner, transport, train")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any config field, e.g. --set learner.lr=1e-4 (repeatable)")


def _config_from(args: argparse.Namespace, shortcuts: dict[str, Any] | None = None,
                 preset: dict[str, Any] | None = None, base: RunConfig | None = None) -> RunConfig:
    """``--config`` file < ``preset`` (a named method's settings) < flag shortcuts < ``--set``."""
    overrides: dict[str, Any] = dict(preset or {})
    overrides.update({k: v for k, v in (shortcuts or {}).items() if v is not None})
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--set {item!r}: write SECTION.FIELD=VALUE")
        overrides[key.strip()] = value
    return load_run_config(args.config, overrides, base=base)


# ---------------------------------------------------------------------------- train


def _train(args: argparse.Namespace) -> int:
    import os

    preset = None
    if args.method:
        from laneshift.experiments import method_settings

        preset = method_settings(args.method, "--method")
    shortcuts = {
        "actor.workers": args.workers, "env.scenario": args.scenario, "replay.demo_mode": args.mode,
        "train.env_steps": args.env_steps, "train.run_dir": args.run_dir, "train.parallel": args.parallel,
        "env.observation": args.observation, "replay.demo_paths": args.demos, "transport.run_id": args.run_id}
    resume = args.resume is not None
    if resume:  # the saved run's config, with this command's flags on top
        saved = Path(args.resume) / "config.yaml"
        if not saved.exists():
            print(f"laneshift train: --resume {args.resume}: no run there (no config.yaml)", file=sys.stderr)
            return 2
        if args.run_dir and Path(args.run_dir).resolve() != Path(args.resume).resolve():
            print("laneshift train: --resume names the run dir; leave out --run-dir", file=sys.stderr)
            return 2
        shortcuts["train.run_dir"] = args.resume
        cfg = _config_from(args, shortcuts, preset, base=load_run_config(saved))
    else:
        cfg = _config_from(args, shortcuts, preset)
    address = args.cluster
    if address is None and not args.local and os.environ.get("RAY_ADDRESS"):
        # Inside `ray job submit` (or with RAY_ADDRESS exported): run on that cluster.
        address = "auto"
        print(f"laneshift train: RAY_ADDRESS={os.environ['RAY_ADDRESS']}: running on that Ray cluster "
              f"(--local for a private one on this machine)", flush=True)
    if address:
        from laneshift.deploy.cluster import train_cluster

        return train_cluster(cfg, address=address, resume=resume, overwrite=args.overwrite)
    from laneshift.deploy.local import train_local

    return train_local(cfg, resume=resume, overwrite=args.overwrite)


def _add_train(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train: local single-machine mode or on a Ray cluster")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--local", action="store_true", help="everything on this machine (the default)")
    where.add_argument("--cluster", metavar="ADDRESS",
                       help="a running Ray cluster: auto (RAY_ADDRESS or this node's cluster), HOST:PORT, "
                            "or ray://HOST:10001")
    p.add_argument("--workers", type=int, help="env workers (Ray actors)")
    p.add_argument("--scenario", help="straight | merge | curve | roundabout | lka")
    p.add_argument("--mode", choices=["none", "retention", "rehearsal", "dqfd"],
                   help="how demos are used (the paper's three, or dqfd: pre-training then retention)")
    p.add_argument("--method", metavar="NAME",
                   help="a named set of settings from `laneshift experiment compare` (none, retention, rehearsal, "
                        "dqfd, dqfd-bc); --mode and --set win over it")
    p.add_argument("--parallel", choices=["async", "sync"], help="MATLAB parallel training mode")
    p.add_argument("--env-steps", help="total env-step budget over all workers")
    p.add_argument("--observation", choices=["vector", "grayscale"])
    p.add_argument("--demos", help="demo shard dir(s), comma separated (default: scripted, generated if absent)")
    p.add_argument("--run-dir", help="where checkpoints, logs, TensorBoard files and config go")
    p.add_argument("--run-id", help="zenoh key namespace (laneshift/<run-id>/...)")
    again = p.add_mutually_exclusive_group()
    again.add_argument("--resume", metavar="RUN_DIR",
                       help="continue a stopped or killed run from its checkpoints (learner state, replay table, "
                            "each worker's remaining budget); flags and --set apply on top of its config")
    again.add_argument("--overwrite", action="store_true", help="start over in a run dir that already holds a run")
    _add_config_args(p)
    p.set_defaults(func=_train)


# ---------------------------------------------------------------------------- services


def _replay_server(args: argparse.Namespace) -> int:
    from laneshift.replay_server.service import run_replay_server

    cfg = _config_from(args, {"replay.http_port": args.http_port, "replay.http_host": args.http_host})
    return run_replay_server(cfg, embedded_router=args.embedded_router, ready_file=args.ready_file)


def _learner(args: argparse.Namespace) -> int:
    from laneshift.learner.loop import run_learner

    return run_learner(_config_from(args))


def _router(args: argparse.Namespace) -> int:
    from laneshift.deploy.router import run_router

    return run_router(args.listen)


def _add_services(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay-server", help="run the replay server process")
    _add_config_args(p)
    p.add_argument("--embedded-router", action="store_true", help="be the zenoh router too (listen on transport.router)")
    p.add_argument("--ready-file", help="write this file once serving (used by the launcher)")
    p.add_argument("--http-port", type=int, help="serve the HTTP inspection API on this port (0 = a free one)")
    p.add_argument("--http-host", help="bind address of the HTTP API (default 127.0.0.1: loopback only)")
    p.set_defaults(func=_replay_server)
    p = sub.add_parser("learner", help="run the learner process")
    _add_config_args(p)
    p.set_defaults(func=_learner)
    p = sub.add_parser("router", help="run a zenoh router for the other processes")
    p.add_argument("--listen", default="tcp/127.0.0.1:7447", help="zenoh endpoint to listen on")
    p.set_defaults(func=_router)


# ---------------------------------------------------------------------------- eval and inspect


def _eval(args: argparse.Namespace) -> int:
    from laneshift.evaluate import evaluate_checkpoint, format_result

    cfg = _config_from(args, {"env.scenario": args.scenario, "env.initial_lane": args.initial_lane,
                              "env.max_steps": args.max_steps, "env.observation": args.observation})
    try:
        result = evaluate_checkpoint(args.checkpoint, cfg.env, episodes=args.episodes, seed=args.seed)
        if args.demo_agreement:
            from laneshift.evaluate import demo_agreement

            result["demo_agreement"] = demo_agreement(args.checkpoint, args.demo_agreement)
    except (ValueError, OSError) as exc:  # a checkpoint of another env or layout, or no such file
        print(f"laneshift eval: {exc}", file=sys.stderr)
        return 2
    if cfg.env.is_lka:
        from laneshift.evaluate import load_greedy_policy, lka_response, plot_lka_response

        greedy = load_greedy_policy(args.checkpoint)
        resp = lka_response(lambda env: greedy)
        png = plot_lka_response(resp, args.png or Path(args.checkpoint).with_suffix(".lka_response.png"))
        result["lka_response"] = {k: v for k, v in resp.items() if k != "trace"} | {"png": str(png)}
    print(json.dumps(result) if args.json else format_result(result))
    return 0


def _replay_inspect(args: argparse.Namespace) -> int:
    from laneshift.replay_server.inspect import inspect_main

    return inspect_main(args)


def _add_inspection(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="greedy evaluation of a checkpoint (survival / achievement rates)")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--scenario")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--initial-lane", choices=["random", "non-target"])
    p.add_argument("--max-steps", type=int, help="episode length (paper evaluation: 300)")
    p.add_argument("--observation", choices=["vector", "grayscale"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.add_argument("--png", help="LKA: where to write the response plot (default: next to the checkpoint)")
    p.add_argument("--demo-agreement", metavar="SHARD",
                   help="also report how often the greedy action is the demonstrator's on this demo shard's states")
    _add_config_args(p)
    p.set_defaults(func=_eval)
    p = sub.add_parser("replay", help="talk to a running replay server")
    rsub = p.add_subparsers(dest="replay_cmd", required=True)
    q = rsub.add_parser("inspect", help="print the replay server's stats")
    q.add_argument("--router", default="tcp/127.0.0.1:7447", help="zenoh router endpoint")
    q.add_argument("--run-id", default="run")
    q.add_argument("--watch", action="store_true", help="refresh every --interval seconds")
    q.add_argument("--interval", type=float, default=2.0)
    q.add_argument("--json", action="store_true")
    q.set_defaults(func=_replay_inspect)


# ---------------------------------------------------------------------------- wiring


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="laneshift", description=__doc__.split("\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_train(sub)
    _add_services(sub)
    _add_inspection(sub)
    demos = sub.add_parser("demos", help="human/scripted demonstrations: record, generate, inspect")
    from laneshift.demos.cli import register as register_demos

    register_demos(demos.add_subparsers(dest="demos_cmd", required=True, metavar="ACTION"))
    experiment = sub.add_parser("experiment", help="reproducible experiments (the paper's Table 2 comparison)")
    from laneshift.checkpoint_curve import register as register_checkpoint_curve
    from laneshift.experiments import register as register_experiments
    from laneshift.reward_study import register as register_presets
    from laneshift.sb3_baseline import register as register_sb3

    which = experiment.add_subparsers(dest="experiment_cmd", required=True, metavar="WHICH")
    register_experiments(which)
    register_checkpoint_curve(which)
    register_sb3(which)
    register_presets(which)
    bench = sub.add_parser("bench", help="benchmarks (env speed, replay throughput)")
    bench_sub = bench.add_subparsers(dest="bench_cmd", required=True, metavar="WHAT")
    from laneshift.bench_env import register as register_bench_env
    from laneshift.bench_replay import register as register_bench_replay
    from laneshift.bench_learner import register as register_bench_learner

    register_bench_env(bench_sub)
    register_bench_replay(bench_sub)
    register_bench_learner(bench_sub)
    from laneshift.deploy.chaos import register as register_chaos

    register_chaos(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ConfigError as exc:
        print(f"laneshift: bad configuration: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
