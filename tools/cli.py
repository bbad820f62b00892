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
import sys
from typing import Any, NoReturn

from laneshift.config import METHODS, ConfigError

from . import cli_inspection, cli_services, cli_train
from .argtypes import add_config_args, config_from

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
    for command in (cli_train, cli_services, cli_inspection):
        command.register(sub)
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
        sys.stdout.write(yaml.safe_dump(config_from(args, preset=preset).to_dict(), sort_keys=False))
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
    add_config_args(s)
    p.set_defaults(func=_config_cmd)


def _add_experiment(sub: Any) -> None:
    experiment = sub.add_parser("experiment", help="reproducible experiments (the paper's Table 2 comparison)")
    from laneshift.tools.studies import (checkpoint_curve, experiments, lka_protocol, paper, protocol,
                                         published_curves, reward_study, sb3_baseline)

    which = experiment.add_subparsers(dest="experiment_cmd", required=True, metavar="WHICH")
    for study in (experiments, protocol, lka_protocol, paper, checkpoint_curve, sb3_baseline, reward_study,
                  published_curves):
        study.register(which)


def _add_bench(sub: Any) -> None:
    bench = sub.add_parser("bench", help="benchmarks (env speed, replay throughput, learner updates)")
    bench_sub = bench.add_subparsers(dest="bench_cmd", required=True, metavar="WHAT")
    from laneshift.tools.bench import env, learner, replay, report, run, run_vs_bound, shards, suite, worker

    for benchmark in (env, replay, learner, run, worker, run_vs_bound, shards, suite, report):
        benchmark.register(bench_sub)


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
