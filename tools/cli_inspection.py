"""``laneshift eval`` (a checkpoint's greedy evaluation, or the scripted driver's: rates, each
episode's outcome, an animated GIF, the agreement with a demo shard, the LKA response; the env taken
from the checkpoint where the user chose none) and
``laneshift replay inspect`` (a running replay server's stats).

Room: the tools (the laneshift command). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from laneshift.tools.argtypes import (add_config_args, config_from, endpoint, fraction, new_file, non_negative_int,
                                      parse_set, positive_float, positive_int)


def _eval(args: argparse.Namespace) -> int:
    from laneshift.tools.studies.evaluate import evaluate_checkpoint, format_result

    shortcuts = {"env.scenario": args.scenario, "env.initial_lane": args.initial_lane,
                 "env.max_steps": args.max_steps, "env.observation": args.observation}
    try:
        picked = _eval_env_from_checkpoint(args) if args.checkpoint else {}
    except (ValueError, OSError) as exc:  # no such file, or not a checkpoint
        config_from(args, shortcuts)  # the config's own errors are reported first
        print(f"laneshift eval: {exc}", file=sys.stderr)
        return 2
    # The checkpoint's settings sit below the user's choices, and the config is checked with them in
    # it: `--set env.shield_gap=2` on a checkpoint trained behind the shield needs no `env.shield`.
    cfg = config_from(args, shortcuts, preset={f"env.{name}": value for name, value in picked.items()})
    try:
        env_cfg = cfg.env
        recorder = None
        if args.video:
            if env_cfg.is_lka:
                raise ValueError(f"--video: the {env_cfg.scenario} env draws no top-down view to record")
            from laneshift.tools.studies.video import GifRecorder

            recorder = GifRecorder(args.video, episodes=min(args.video_episodes, args.episodes),
                                   fps=args.video_fps, scale=args.video_scale)
        outcomes: list[dict] | None = [] if args.episodes_out else None
        if args.driver:  # the scripted driver on the same episodes, to compare with a network's
            if env_cfg.is_lka or args.demo_agreement:
                raise ValueError("--driver: the scripted driver drives the lane-change roads only, and has no "
                                 "greedy actions to compare with a demo shard (--demo-agreement)")
            from laneshift.actors.envs.demonstrator import ScriptedDriver
            from laneshift.tools.studies.evaluate import evaluate_policy

            result = evaluate_policy(ScriptedDriver, env_cfg, args.episodes, args.seed, progress="eval",
                                     recorder=recorder, outcomes=outcomes)
        else:
            result = evaluate_checkpoint(args.checkpoint, env_cfg, episodes=args.episodes, seed=args.seed,
                                         progress="eval", recorder=recorder, outcomes=outcomes)
        if outcomes is not None:  # one JSON object a line, an episode each
            from laneshift.tools.studies.provenance import write_whole

            write_whole(args.episodes_out, "".join(json.dumps(o) + "\n" for o in outcomes))
            result["episodes_out"] = str(args.episodes_out)
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


def _eval_env_from_checkpoint(args: argparse.Namespace) -> dict[str, str | bool | float]:
    """The env settings ``laneshift eval`` takes from the checkpoint's metadata (its observation
    type, scenario, layout options and shield) where the user chose none: not by a flag, ``--set`` or
    the ``--config`` file; only those that differ from the defaults. An explicit choice that
    contradicts the checkpoint is kept, and refused by the evaluation with what would fit."""
    from laneshift.actors.evaluation import checkpoint_env_settings
    from laneshift.config import EnvConfig, read_config_file
    from laneshift.wire import safetensors_loads

    chosen = {name for name in ("scenario", "observation") if getattr(args, name) is not None}
    chosen |= {key.removeprefix("env.") for key in parse_set(args.set) if key.startswith("env.")}
    if args.config:
        chosen |= set(read_config_file(args.config).get("env", {}))
    _, meta = safetensors_loads(Path(args.checkpoint).read_bytes())
    defaults = EnvConfig()
    return {name: value for name, value in checkpoint_env_settings(meta).items()
            if name not in chosen and getattr(defaults, name) != value}


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
    from laneshift.replay_server.stats_table import inspect_main

    # inspect_main's session waits for a router forever (what services want): first make sure one
    # answers, giving up after --connect-timeout with the endpoint named.
    try:
        transport.open_session(TransportConfig(router=args.router, run_id=args.run_id),
                               connect_timeout_s=args.connect_timeout).close()
    except ConnectionError as exc:
        print(f"laneshift replay inspect: {exc}", file=sys.stderr)
        return 1
    return inspect_main(args)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="greedy evaluation of a checkpoint or the scripted driver (survival / achievement rates)")
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--checkpoint", help="a learner checkpoint (.safetensors), e.g. "
                                          "RUN_DIR/checkpoints/final.safetensors")
    who.add_argument("--driver", choices=["scripted"],
                     help="evaluate the scripted driver (the demonstrator) instead, on the same episodes")
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
    p.add_argument("--episodes-out", type=new_file, metavar="PATH.jsonl",
                   help="also write each episode's outcome, a JSON line each (seed, start and end lane, steps, "
                        "return, survived, achieved, crash kind, shielded steps): compare policies episode by episode")
    p.add_argument("--png", help="LKA: where to write the response plot (default: next to the checkpoint)")
    p.add_argument("--demo-agreement", metavar="SHARD",
                   help="also report how often the greedy action is the demonstrator's on this demo shard's states")
    add_config_args(p)
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
