"""``laneshift train``: its flags (each shortcut flag names the config field it sets and that
field's default), ``--resume`` and ``--overwrite``, and the run it starts: on this machine
(``deploy.local``) or on a Ray cluster (``deploy.cluster``: ``--cluster``, or ``RAY_ADDRESS``).

The launcher's process lives as long as the run: this module imports no tool (the parser of
``laneshift train`` is built without them, ``cli.build_parser``).

Room: the tools (the laneshift command). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from laneshift.config import METHODS, RunConfig, load_run_config
from laneshift.tools.argtypes import add_config_args, config_from, positive_int


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
        cfg = config_from(args, shortcuts, preset, base=load_run_config(saved))
    else:
        cfg = config_from(args, shortcuts, preset)
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


def register(sub: argparse._SubParsersAction) -> None:
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
    add_config_args(p)
    for action in p._actions:  # a shortcut's default is the config field's: say which and what it is
        if action.dest in TRAIN_SHORTCUTS and "default" not in (action.help or ""):
            action.help = f"{action.help} {_config_default(TRAIN_SHORTCUTS[action.dest])}"
    p.set_defaults(func=_train)
