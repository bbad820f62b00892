"""``laneshift demos ...`` sub-commands: generate, record, inspect.

The ``laneshift`` command (``laneshift.tools.cli``) calls :func:`register` on the ``demos`` sub-parsers;
each sub-command sets ``func(args) -> int``. Standalone: ``python -m laneshift.tools.demos.cli generate ...``.

Example::

    laneshift demos generate --scenario straight --episodes 50 --out runs/demos/straight
    laneshift demos generate --scenario straight --episodes 50 --out runs/demos/stand-in \
        --driver human-like          # scripted driver + reaction delay + action noise; not a person
    laneshift demos record --scenario straight --episodes 20 --out runs/demos/human
    laneshift demos inspect runs/demos/straight        # also writes runs/demos/straight_returns.png

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..argtypes import non_negative_float, non_negative_int, positive_float, positive_int
from .humanlike import DEFAULT_ACTION_NOISE, DEFAULT_REACTION_STEPS
from laneshift.demos.shard import ShardError


def _probability(text: str) -> float:
    """A float in [0, 1] (argparse type)."""
    value = non_negative_float(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must be a probability in [0, 1], got {text}")
    return value


def _json_or_str(text: str) -> Any:
    """JSON when it parses (numbers, true, null, lists), else the text itself."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def _kwarg(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` -> (key, value), VALUE through :func:`_json_or_str`."""
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, _json_or_str(value)


def env_kwargs_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The flat env kwargs given on the command line (only those given: env defaults apply)."""
    kwargs: dict[str, Any] = dict(args.env_kwarg or [])
    for name in ("observation", "max_steps", "reward_preset", "initial_lane"):
        value = getattr(args, name, None)
        if value is not None:
            kwargs[name] = value
    return kwargs


def _add_env_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", required=True,
                        help="scenario name (straight, merge, curve, roundabout, allroads, lka) or gymnasium id")
    parser.add_argument("--observation", choices=("vector", "grayscale"),
                        help="observation type (default: the env's)")
    parser.add_argument("--max-steps", type=positive_int, help="episode length limit (env kwarg max_steps)")
    parser.add_argument("--reward-preset", type=positive_int,
                        help="reward condition (env kwarg reward_preset: 1-5, docs/environments.md)")
    parser.add_argument("--initial-lane", type=_json_or_str,
                        help="initial lane (env kwarg initial_lane)")
    parser.add_argument("--env-kwarg", type=_kwarg, action="append", metavar="KEY=VALUE",
                        help="any other env kwarg (repeatable; VALUE parsed as JSON if it can be)")


def _cmd_generate(args: argparse.Namespace) -> int:
    from .generate import generate_shard
    from laneshift.demos.shard import read_metadata

    try:
        if args.driver != "human-like" and (args.reaction_steps is not None
                                            or args.action_noise is not None):
            raise ValueError("--reaction-steps / --action-noise need --driver human-like")
        path = generate_shard(args.out, env_id_or_scenario=args.scenario,
                              env_kwargs=env_kwargs_from_args(args), episodes=args.episodes,
                              seed=args.seed, progress="demos generate", policy=args.driver,
                              reaction_steps=args.reaction_steps, action_noise=args.action_noise,
                              achieved_only=args.achieved_only)
    except (FileExistsError, ValueError) as exc:  # bad arguments / existing output
        print(f"{_prog(args)}: {exc}", file=sys.stderr)
        return 2
    meta = read_metadata(path)
    print(f"wrote {path}: {meta['episodes']} episodes, {meta['steps']} steps of {meta['env_id']} "
          f"in {meta.get('generation_seconds', float('nan')):.1f} s; demonstrator survival "
          f"{_rate(meta.get('survival_rate'))}, achievement {_rate(meta.get('achievement_rate'))}")
    if meta.get("achieved_only"):
        print(f"kept the episodes that ended on the target lane: {meta['discarded_episodes']} more driven and "
              f"left out (achievement over all driven: {_rate(meta['driven_achievement_rate'])})")
    if args.driver == "human-like":  # never let a stand-in pass for a person
        print(f"recorded by: {meta['recorded_by']}")
    return 0


def _prog(args: argparse.Namespace) -> str:
    """The command's name for an error line (``laneshift demos generate``)."""
    return getattr(args, "cli_prog", None) or "laneshift demos"


def _rate(rate: float | None) -> str:
    return "n/a" if rate is None else f"{100 * rate:.1f} %"


def _cmd_record(args: argparse.Namespace) -> int:
    from .record import record_shard

    try:
        path = record_shard(args.out, env_id_or_scenario=args.scenario,
                            env_kwargs=env_kwargs_from_args(args), episodes=args.episodes,
                            seed=args.seed, fps=args.fps, scale=args.scale)
    except (FileExistsError, ValueError) as exc:
        print(f"{_prog(args)}: {exc}", file=sys.stderr)
        return 2
    if path is None:
        print("no episode was completed: nothing written", file=sys.stderr)
        return 1
    from laneshift.demos.shard import read_metadata

    meta = read_metadata(path)
    print(f"wrote {path}: {meta['episodes']} human episodes, {meta['steps']} steps "
          f"({meta.get('discarded_episodes', 0)} discarded); survival "
          f"{_rate(meta.get('survival_rate'))}, achievement {_rate(meta.get('achievement_rate'))}")
    return 0


def _cmd_inspect(args: argparse.Namespace) -> int:
    from .inspection import format_summary, plot_returns, summarize
    from laneshift.demos.shard import read_verified

    try:
        episodes = read_verified(args.shard)  # checksum verified; no flat copy of the obs
    except ShardError as exc:
        print(f"{_prog(args)}: {exc}", file=sys.stderr)
        return 2
    summary = summarize(episodes)
    directory = Path(args.shard).absolute()
    png = Path(args.png) if args.png else directory.with_name(f"{directory.name}_returns.png")
    summary["returns_png"] = str(plot_returns(summary, png))
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
        print(f"return plot  {summary['returns_png']}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the demos sub-commands (``generate``, ``record``, ``inspect``) to ``subparsers``."""
    generate = subparsers.add_parser(
        "generate", help="record scripted-driver demonstrations into a demo shard",
        description="Run the scripted demonstrator and write a demo shard (Minari dataset).")
    _add_env_arguments(generate)
    generate.add_argument("--episodes", type=positive_int, required=True, help="episodes to drive and record")
    generate.add_argument("--out", required=True,
                          help="shard directory to create (must not exist or be empty)")
    generate.add_argument("--seed", type=non_negative_int, default=0,
                          help="episode i is reset with seed SEED+i (default 0)")
    generate.add_argument("--driver", choices=("scripted", "human-like"), default="scripted",
                          help="scripted: the rule-based expert (default); human-like: a stand-in "
                               "for a person (the expert with a reaction delay and action noise, "
                               "labelled 'not a person' in the shard)")
    generate.add_argument("--reaction-steps", type=non_negative_int,
                          help="human-like: act on the state of this many steps ago "
                               f"(default {DEFAULT_REACTION_STEPS}, calibrated; see docs/demos.md)")
    generate.add_argument("--action-noise", type=_probability,
                          help="human-like: probability of a uniformly random action instead "
                               f"(default {DEFAULT_ACTION_NOISE:g}, calibrated)")
    generate.add_argument("--achieved-only", action="store_true",
                          help="keep only episodes that end alive on the target lane, driving further seeds "
                               "until EPISODES are kept (lane-change scenarios)")
    generate.set_defaults(func=_cmd_generate)

    record = subparsers.add_parser(
        "record", help="drive with the keyboard and record human demonstrations",
        description="Open a window and record keyboard-driven episodes: arrows = speed +/- and "
                    "turn left/right (combinations allowed), P pause, Backspace discard the "
                    "episode, Esc/Q quit (completed episodes are saved).")
    _add_env_arguments(record)
    record.add_argument("--episodes", type=positive_int, required=True,
                        help="episodes to complete (fewer when you quit early)")
    record.add_argument("--out", required=True,
                        help="shard directory to create (must not exist or be empty)")
    record.add_argument("--seed", type=non_negative_int, default=0,
                        help="episode attempt k is reset with seed SEED+k (default 0)")
    record.add_argument("--fps", type=non_negative_float,
                        help="env steps per second (default: the env's render_fps; 0: as fast as frames are drawn)")
    record.add_argument("--scale", type=positive_float, default=1.0, help="window zoom factor")
    record.set_defaults(func=_cmd_record)

    inspect = subparsers.add_parser(
        "inspect", help="summarise a demo shard and plot its return distribution",
        description="Verify a demo shard and print episodes, steps, returns, success rates "
                    "and the action histogram; write a PNG of the episode returns.")
    inspect.add_argument("shard", help="shard directory")
    inspect.add_argument("--png", help="where to write the return histogram "
                                       "(default: DIR_returns.png next to the shard)")
    inspect.add_argument("--json", action="store_true", help="print the summary as JSON")
    inspect.set_defaults(func=_cmd_inspect)


def main(argv: list[str] | None = None) -> int:
    """Standalone entry point: ``python -m laneshift.tools.demos.cli {generate,record,inspect} ...``."""
    parser = argparse.ArgumentParser(prog="laneshift demos")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    raise SystemExit(main())
