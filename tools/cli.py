"""laneshift: distributed Double DQN for lane changes (Ray env workers, a zenoh replay server
holding human/scripted demonstrations, a torch learner).

examples:
    laneshift train --local --workers 2 --scenario straight --method dqfd-bc --env-steps 30000 --run-dir runs/demo
    laneshift replay-server --config runs/demo/config.yaml
    laneshift learner --config runs/demo/config.yaml
    laneshift demos generate --scenario straight --episodes 50 --out demos/straight
    laneshift eval --checkpoint runs/demo/checkpoints/final.safetensors --scenario straight --episodes 200
    laneshift replay inspect --router tcp/127.0.0.1:7447 --run-id run
    laneshift bench env

`laneshift COMMAND --help` lists a command's options with their defaults. Long commands report
progress on stderr (a bar on a terminal, a line every 10 s otherwise; LANESHIFT_PROGRESS=0: none).
Bad input exits with code 2 and one line saying what is wrong.

Room: the tools (the laneshift command). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, NoReturn

from .argtypes import add_set_arg, endpoint, fraction, non_negative_int, parse_set, positive_float, positive_int
from laneshift.config import METHODS, ConfigError, RunConfig, load_run_config

# ---------------------------------------------------------------------------- parser pieces


class HelpFormatter(argparse.HelpFormatter):
    """Every option's default shown after its help, unless the help already says it or there is
    none to show (None, an empty list, an on/off flag). A description with indented lines (examples)
    is kept as written; others are wrapped."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n    " in text:
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        empty = default is None or default is argparse.SUPPRESS or (
            isinstance(default, (str, list, tuple)) and not default)
        if not action.option_strings or action.nargs == 0 or "default" in text.lower() or empty:
            return text
        shown = ",".join(map(str, default)) if isinstance(default, (list, tuple)) else "%(default)s"
        return f"{text} (default: {shown})"


class Parser(argparse.ArgumentParser):
    """The laneshift parser (its sub-parsers are of this class too): defaults in --help, and a
    usage error as one line on stderr, exit code 2."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> "NoReturn":  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", help="YAML/TOML/JSON file with sections env, actor, replay, learner, transport, train")
    add_set_arg(p)


def _config_from(args: argparse.Namespace, shortcuts: dict[str, Any] | None = None,
                 preset: dict[str, Any] | None = None, base: RunConfig | None = None) -> RunConfig:
    """``--config`` file < ``preset`` (a named method's settings) < flag shortcuts < ``--set``."""
    overrides: dict[str, Any] = dict(preset or {})
    overrides.update({k: v for k, v in (shortcuts or {}).items() if v is not None})
    overrides.update(parse_set(args.set))
    return load_run_config(args.config, overrides, base=base)


# ---------------------------------------------------------------------------- train


def _train(args: argparse.Namespace) -> int:
    preset = None
    if args.method:
        from laneshift.config import method_settings

        preset = method_settings(args.method, "--method")
    shortcuts = {field: getattr(args, dest) for dest, field in TRAIN_SHORTCUTS.items()}
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


#: train's flags that set a config field (argparse dest -> section.field); their defaults are the config's.
TRAIN_SHORTCUTS = {
    "workers": "actor.workers", "scenario": "env.scenario", "mode": "replay.demo_mode", "env_steps": "train.env_steps",
    "run_dir": "train.run_dir", "parallel": "train.parallel", "observation": "env.observation",
    "demos": "replay.demo_paths", "run_id": "transport.run_id"}


def _config_default(field: str) -> str:
    """``(default: section.field = value)``: what a shortcut flag leaves in place when it is not given."""
    section, name = field.split(".")
    value = getattr(getattr(RunConfig(), section), name)
    shown = ",".join(map(str, value)) if isinstance(value, tuple) else value
    return f"(default: {field} = {shown if shown not in ('', ()) else 'none'})"


def _add_train(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train: local single-machine mode or on a Ray cluster")
    where = p.add_mutually_exclusive_group()
    ray_address = os.environ.get("RAY_ADDRESS")
    where.add_argument("--local", action="store_true",
                       help="everything on this machine " + (f"(RAY_ADDRESS={ray_address} is set, so without --local "
                                                             "the run goes to that cluster)" if ray_address
                                                             else "(the default; with RAY_ADDRESS set, that cluster is)"))
    where.add_argument("--cluster", metavar="ADDRESS",
                       help="a running Ray cluster: auto (RAY_ADDRESS or this node's cluster), HOST:PORT, "
                            "or ray://HOST:10001")
    p.add_argument("--workers", type=positive_int, help="env workers (Ray actors)")
    p.add_argument("--scenario", help="straight | merge | curve | roundabout | allroads | lka")
    p.add_argument("--mode", choices=["none", "retention", "rehearsal", "dqfd"],
                   help="how demos are used (the paper's three, or dqfd: pre-training then retention)")
    p.add_argument("--method", metavar="NAME",
                   help="a named set of settings (" + ", ".join(METHODS) + "; docs/RESULTS.md measures them); "
                        "--mode and --set win over it")
    p.add_argument("--parallel", choices=["async", "sync"], help="MATLAB parallel training mode")
    p.add_argument("--env-steps", help="total env-step budget over all workers")
    p.add_argument("--observation", choices=["vector", "grayscale"],
                   help="what the network sees: a feature vector or stacked grayscale frames")
    p.add_argument("--demos", help="demo shard dir(s), comma separated (default: the scripted driver's, generated if "
                                   "absent, for a demo mode)")
    p.add_argument("--run-dir", help="where checkpoints, logs, TensorBoard files and config go")
    p.add_argument("--run-id", help="zenoh key namespace (laneshift/<run-id>/...)")
    again = p.add_mutually_exclusive_group()
    again.add_argument("--resume", metavar="RUN_DIR",
                       help="continue a stopped or killed run from its checkpoints (learner state, replay table, "
                            "each worker's remaining budget); flags and --set apply on top of its config")
    again.add_argument("--overwrite", action="store_true", help="start over in a run dir that already holds a run")
    _add_config_args(p)
    for action in p._actions:  # a shortcut's default is the config field's: say which and what it is
        if action.dest in TRAIN_SHORTCUTS and "default" not in (action.help or ""):
            action.help = f"{action.help} {_config_default(TRAIN_SHORTCUTS[action.dest])}"
    p.set_defaults(func=_train)


# ---------------------------------------------------------------------------- services


def _end_service_process(rc: int) -> NoReturn:
    """End a service process (replay server, learner, router) once it has stopped cleanly: flush
    the std streams and ``os._exit(rc)``, skipping interpreter finalization.

    Why: zenoh-python is Rust (pyo3). A thread that returns from a zenoh call (a channel's
    ``recv()``, a session's ``close()`` that timed out) while CPython 3.11 finalizes is ended with
    ``pthread_exit``; its forced unwind is caught by pyo3's panic guard and glibc aborts the
    process ("FATAL: exception not rethrown", SIGABRT) after the final checkpoint and stats were
    written. CI saw it once on a replay server's SIGTERM. Every file the service writes is
    written and closed before this point, so finalization has nothing left to do for us."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken pipe: nothing more to say anyway
            pass
    os._exit(rc)


def _replay_server(args: argparse.Namespace) -> int:
    from laneshift.actors.envs import spec_of
    from laneshift.replay_server.service import run_replay_server

    cfg = _config_from(args, {"replay.http_port": args.http_port, "replay.http_host": args.http_host})
    # The one env this process builds: to learn the observation's shape and the action count.
    return _end_service_process(run_replay_server(cfg, spec_of(cfg.env), embedded_router=args.embedded_router,
                                                  ready_file=args.ready_file, shard=args.shard))


def _learner(args: argparse.Namespace) -> int:
    from laneshift.deploy.builder import Builder
    from laneshift.learner.process import run_learner

    builder = Builder(_config_from(args))  # the env's spec and the periodic greedy evaluation
    return _end_service_process(run_learner(builder.cfg, builder.spec, builder.greedy_evaluation()))


def _router(args: argparse.Namespace) -> int:
    from laneshift.deploy.router import run_router

    return _end_service_process(run_router(args.listen))


def _add_services(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay-server", help="run the replay server process")
    _add_config_args(p)
    p.add_argument("--embedded-router", action="store_true", help="be the zenoh router too (listen on transport.router)")
    p.add_argument("--ready-file", help="write this file once serving (used by the launcher)")
    p.add_argument("--http-port", type=non_negative_int,
                   help="serve the HTTP inspection API on this port (0 = a free one)")
    p.add_argument("--http-host", help="bind address of the HTTP API (default 127.0.0.1: loopback only)")
    p.add_argument("--shard", type=non_negative_int, default=0,
                   help="which shard of replay.shards this server is (default 0; a fixed HTTP port becomes "
                        "port + shard)")
    p.set_defaults(func=_replay_server)
    p = sub.add_parser("learner", help="run the learner process")
    _add_config_args(p)
    p.set_defaults(func=_learner)
    p = sub.add_parser("router", help="run a zenoh router for the other processes")
    p.add_argument("--listen", type=endpoint, default="tcp/127.0.0.1:7447", help="zenoh endpoint to listen on")
    p.set_defaults(func=_router)


# ---------------------------------------------------------------------------- eval and inspect


def _eval(args: argparse.Namespace) -> int:
    import dataclasses

    from laneshift.tools.studies.evaluate import evaluate_checkpoint, format_result

    cfg = _config_from(args, {"env.scenario": args.scenario, "env.initial_lane": args.initial_lane,
                              "env.max_steps": args.max_steps, "env.observation": args.observation})
    try:
        picked = _eval_env_from_checkpoint(args, cfg)
        env_cfg = dataclasses.replace(cfg.env, **picked)
        recorder = None
        if args.video:
            if env_cfg.is_lka:
                raise ValueError(f"--video: the {env_cfg.scenario} env draws no top-down view to record")
            from laneshift.tools.studies.video import GifRecorder

            recorder = GifRecorder(args.video, episodes=min(args.video_episodes, args.episodes),
                                   fps=args.video_fps, scale=args.video_scale)
        result = evaluate_checkpoint(args.checkpoint, env_cfg, episodes=args.episodes, seed=args.seed,
                                     progress="eval", recorder=recorder)
        if recorder is not None:
            result["video"] = recorder.write()
        if args.demo_agreement:
            from laneshift.tools.studies.evaluate import demo_agreement

            result["demo_agreement"] = demo_agreement(args.checkpoint, args.demo_agreement)
    except (ValueError, OSError) as exc:  # a checkpoint of another env or layout, or no such file
        print(f"laneshift eval: {exc}", file=sys.stderr)
        return 2
    if picked:  # after the checks: a refusal stays one line
        print("laneshift eval: from the checkpoint: " + ", ".join(f"{k} {v}" for k, v in picked.items()),
              file=sys.stderr)
    if env_cfg.is_lka:
        from laneshift.tools.studies.evaluate import load_greedy_policy, lka_response, plot_lka_response

        greedy = load_greedy_policy(args.checkpoint)
        resp = lka_response(lambda env: greedy)
        png = plot_lka_response(resp, args.png or Path(args.checkpoint).with_suffix(".lka_response.png"))
        result["lka_response"] = {k: v for k, v in resp.items() if k != "trace"} | {"png": str(png)}
    print(json.dumps(result) if args.json else format_result(result))
    return 0


def _eval_env_from_checkpoint(args: argparse.Namespace, cfg: RunConfig) -> dict[str, str]:
    """The env settings ``laneshift eval`` takes from the checkpoint's metadata (its observation
    type, scenario and layout options) where the user chose none: not by a flag, ``--set`` or the ``--config``
    file; only those that differ from the config's. An explicit choice that contradicts the
    checkpoint is kept, and refused by the evaluation with what would fit."""
    from laneshift.actors.evaluation import checkpoint_env_settings
    from laneshift.config import read_config_file
    from laneshift.wire import safetensors_loads

    chosen = {name for name in ("scenario", "observation") if getattr(args, name) is not None}
    chosen |= {key.removeprefix("env.") for key in parse_set(args.set) if key.startswith("env.")}
    if args.config:
        chosen |= set(read_config_file(args.config).get("env", {}))
    _, meta = safetensors_loads(Path(args.checkpoint).read_bytes())
    return {name: value for name, value in checkpoint_env_settings(meta).items()
            if name not in chosen and getattr(cfg.env, name) != value}


def video_path(text: str) -> str:
    """argparse type: a path ``--video`` can write (a .gif)."""
    from laneshift.tools.studies.video import check_video_path

    try:
        return str(check_video_path(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _replay_inspect(args: argparse.Namespace) -> int:
    from laneshift import transport
    from laneshift.config import TransportConfig
    from laneshift.replay_server.inspect import inspect_main

    # inspect_main's session waits for a router forever (what services want): first make sure one
    # answers, giving up after --connect-timeout with the endpoint named.
    try:
        transport.open_session(TransportConfig(router=args.router, run_id=args.run_id),
                               connect_timeout_s=args.connect_timeout).close()
    except ConnectionError as exc:
        print(f"laneshift replay inspect: {exc}", file=sys.stderr)
        return 1
    return inspect_main(args)


def _add_inspection(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="greedy evaluation of a checkpoint (survival / achievement rates)")
    p.add_argument("--checkpoint", required=True, help="a learner checkpoint (.safetensors), e.g. "
                                                       "RUN_DIR/checkpoints/final.safetensors")
    p.add_argument("--scenario", help="straight | merge | curve | roundabout | allroads | lka (default: the "
                                      "checkpoint's env, else the config's); allroads on one road: --set env.road=ROAD")
    p.add_argument("--episodes", type=positive_int, default=100, help="greedy evaluation episodes")
    p.add_argument("--initial-lane", choices=["random", "non-target"],
                   help="where episodes start: any lane, or never the target lane (default: the config's)")
    p.add_argument("--max-steps", type=positive_int, help="episode length (paper evaluation: 300)")
    p.add_argument("--observation", choices=["vector", "grayscale"],
                   help="observation type; must be the one the checkpoint was trained on (default: the checkpoint's)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="episode i is reset with seed SEED+i")
    p.add_argument("--video", type=video_path, metavar="PATH.gif",
                   help="also write the first --video-episodes episodes as an animated GIF (the top-down view)")
    p.add_argument("--video-episodes", type=positive_int, default=1, metavar="N",
                   help="how many episodes --video shows")
    p.add_argument("--video-fps", type=positive_float, metavar="FPS",
                   help="--video frames per second of real time; fewer than the policy frequency keeps every "
                        "k-th step (default: every step, 10 on the lane-change roads)")
    p.add_argument("--video-scale", type=fraction, default=1.0, metavar="FACTOR",
                   help="--video image size factor (1: 600 x 300 pixels)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--png", help="LKA: where to write the response plot (default: next to the checkpoint)")
    p.add_argument("--demo-agreement", metavar="SHARD",
                   help="also report how often the greedy action is the demonstrator's on this demo shard's states")
    _add_config_args(p)
    p.set_defaults(func=_eval)
    p = sub.add_parser("replay", help="talk to a running replay server")
    rsub = p.add_subparsers(dest="replay_cmd", required=True, metavar="ACTION")
    q = rsub.add_parser("inspect", help="print the replay server's stats")
    q.add_argument("--router", type=endpoint, default="tcp/127.0.0.1:7447", help="zenoh router endpoint")
    q.add_argument("--run-id", default="run", help="the run's zenoh key namespace (transport.run_id)")
    q.add_argument("--connect-timeout", type=positive_float, default=5.0, metavar="SECONDS",
                   help="give up when no router answers at --router within this long")
    q.add_argument("--watch", action="store_true", help="refresh every --interval seconds")
    q.add_argument("--interval", type=positive_float, default=2.0, metavar="SECONDS",
                   help="seconds between two refreshes of --watch")
    q.add_argument("--json", action="store_true", help="print the stats as JSON")
    q.add_argument("--shards", type=positive_int, default=1,
                   help="the run's replay.shards: with more than one, every shard's stats summed (default 1)")
    q.add_argument("--shard", type=non_negative_int, help="only this shard's stats (with --shards)")
    q.set_defaults(func=_replay_inspect)


# ---------------------------------------------------------------------------- wiring


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("laneshift")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "unknown (not installed)"


#: Commands whose tools live in modules of their own (they register their sub-commands).
TOOL_COMMANDS = ("demos", "experiment", "bench", "chaos")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The laneshift command's parser: every command, or (``argv`` given) the core commands plus
    the tool command ``argv`` runs: all of them when ``argv`` is None or names no core command (then
    every command is listed, as in ``laneshift --help``).

    Why: ``laneshift train``'s process is the run's launcher, which lives as long as the run, and
    the tools' modules import gymnasium, matplotlib and the demo and study code: 0.52 -> 0.09 s of
    CPU before Ray starts and 65 -> 18 MB of RSS (measured: a process building ``build_parser()``
    against ``build_parser(["train"])``)."""
    parser = Parser(prog="laneshift", description=__doc__.split("\nRoom:")[0].rstrip())
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}",
                        help="print laneshift's version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_train(sub)
    _add_services(sub)
    _add_inspection(sub)
    _add_config(sub)
    # The top level has no option that takes a value: the first other word is the command.
    command = next((a for a in argv if not a.startswith("-")), None) if argv is not None else None
    if command in TOOL_COMMANDS:
        wanted = {command}
    elif command in sub.choices:  # a core command
        wanted = set()
    else:  # none, or a word that is no command: argparse lists them all
        wanted = set(TOOL_COMMANDS)
    if "demos" in wanted:
        demos = sub.add_parser("demos", help="human/scripted demonstrations: record, generate, inspect")
        from laneshift.tools.demos.cli import register as register_demos

        register_demos(demos.add_subparsers(dest="demos_cmd", required=True, metavar="ACTION"))
    if "experiment" in wanted:
        _add_experiment(sub)
    if "bench" in wanted:
        _add_bench(sub)
    if "chaos" in wanted:
        from laneshift.tools.chaos import register as register_chaos

        register_chaos(sub)
    for command_parser in leaf_parsers(parser):  # errors name the command they came from
        command_parser.set_defaults(cli_prog=command_parser.prog)
    return parser


def _config_cmd(args: argparse.Namespace) -> int:
    from laneshift.tools import config_reference as ref

    if args.config_cmd == "fields":
        fields = ref.find(args.text or "")
        if not fields:
            print(f"laneshift config fields: no field or meaning contains {args.text!r}", file=sys.stderr)
            return 2
        sys.stdout.write(ref.as_text(fields))
    elif args.config_cmd == "reference":
        sys.stdout.write(ref.as_markdown())
    elif args.config_cmd == "methods":
        for name, settings in METHODS.items():
            print(f"{name}: " + (", ".join(f"{k}={v}" for k, v in settings.items())))
    else:  # show
        import yaml

        preset = None
        if args.method:
            from laneshift.config import method_settings

            preset = method_settings(args.method, "--method")
        sys.stdout.write(yaml.safe_dump(_config_from(args, preset=preset).to_dict(), sort_keys=False))
    return 0


def _add_config(sub: Any) -> None:
    p = sub.add_parser("config", help="the configuration: every field with its meaning, a resolved config, "
                                      "the method presets")
    which = p.add_subparsers(dest="config_cmd", required=True, metavar="WHAT")
    f = which.add_parser("fields", help="every config field (or those whose name or meaning contains TEXT): "
                                        "type, default, meaning")
    f.add_argument("text", nargs="?", metavar="TEXT", help="a section (replay), a field (lr) or a word (epsilon)")
    which.add_parser("reference", help="the configuration reference as markdown (docs/config.md)")
    which.add_parser("methods", help="the named method presets (--method) and the fields each sets")
    s = which.add_parser("show", help="the config a run would get from --config, --method and --set, as YAML")
    s.add_argument("--method", metavar="NAME", help=f"a method preset ({', '.join(METHODS)})")
    _add_config_args(s)
    p.set_defaults(func=_config_cmd)


def _add_experiment(sub: Any) -> None:
    experiment = sub.add_parser("experiment", help="reproducible experiments (the paper's Table 2 comparison)")
    from laneshift.tools.studies.checkpoint_curve import register as register_checkpoint_curve
    from laneshift.tools.studies.experiments import register as register_experiments
    from laneshift.tools.studies.paper import register as register_paper
    from laneshift.tools.studies.protocol import register as register_protocol
    from laneshift.tools.studies.reward_study import register as register_presets
    from laneshift.tools.studies.sb3_baseline import register as register_sb3

    which = experiment.add_subparsers(dest="experiment_cmd", required=True, metavar="WHICH")
    register_experiments(which)
    register_protocol(which)
    register_paper(which)
    register_checkpoint_curve(which)
    register_sb3(which)
    register_presets(which)


def _add_bench(sub: Any) -> None:
    bench = sub.add_parser("bench", help="benchmarks (env speed, replay throughput, learner updates)")
    bench_sub = bench.add_subparsers(dest="bench_cmd", required=True, metavar="WHAT")
    from laneshift.tools.bench.env import register as register_bench_env
    from laneshift.tools.bench.learner import register as register_bench_learner
    from laneshift.tools.bench.replay import register as register_bench_replay
    from laneshift.tools.bench.report import register as register_bench_report
    from laneshift.tools.bench.run import register as register_bench_run
    from laneshift.tools.bench.run_vs_bound import register as register_bench_run_vs_bound
    from laneshift.tools.bench.shards import register as register_bench_shards
    from laneshift.tools.bench.suite import register as register_bench_all
    from laneshift.tools.bench.worker import register as register_bench_worker

    register_bench_env(bench_sub)
    register_bench_replay(bench_sub)
    register_bench_learner(bench_sub)
    register_bench_run(bench_sub)
    register_bench_worker(bench_sub)
    register_bench_run_vs_bound(bench_sub)
    register_bench_shards(bench_sub)
    register_bench_all(bench_sub)
    register_bench_report(bench_sub)


def leaf_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """Every command parser under ``parser`` that runs something (has no sub-commands)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        return [parser]
    return [leaf for a in subs for child in dict.fromkeys(a.choices.values()) for leaf in leaf_parsers(child)]


def _zenoh_message(exc: BaseException) -> str:
    """zenoh's error text without the Rust source location it appends."""
    import re

    return re.sub(r" at /\S+?:\d+\.?", "", str(exc)).strip()


#: What the `laneshift` command needs beyond the environments (pyproject's `train` extra).
TRAIN_EXTRA_MODULES = ("tqdm", "zenoh", "torch", "ray")


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser(sys.argv[1:] if argv is None else argv)
    except ModuleNotFoundError as exc:  # a core-only install: the environments, not the command
        if exc.name not in TRAIN_EXTRA_MODULES:
            raise
        print(f"laneshift: {exc.name} is not installed: the laneshift command needs the train extra "
              f"(pip install 'laneshift[train]', torch first: python deploy/install_torch.py)", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    prog = getattr(args, "cli_prog", "laneshift")
    try:
        return int(args.func(args) or 0)
    except ConfigError as exc:
        print(f"{prog}: bad configuration: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # a command's own input check: raise SystemExit("what is wrong")
        if isinstance(exc.code, str):
            named = exc.code.startswith(prog.removeprefix("laneshift ") + ":")  # "bench learner: ..."
            print(f"laneshift {exc.code}" if named else f"{prog}: {exc.code}", file=sys.stderr)
            return 2
        raise
    except KeyboardInterrupt:
        return 130
    except Exception as exc:
        if type(exc).__name__ == "ZError" and type(exc).__module__.startswith("zenoh"):
            print(f"{prog}: zenoh: {_zenoh_message(exc)}", file=sys.stderr)
            return 1
        raise


if __name__ == "__main__":
    raise SystemExit(main())
