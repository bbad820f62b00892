"""A protocol's final networks published (``publish_run``, one seed's): each seed's as
``<road>-<method>-seed<N>-final.safetensors`` with a ``.json`` beside it (command line, git
revision, resolved config, test table), and for each test rate the ``laneshift eval`` command that
reproduces it (``eval_command``).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import shutil
from pathlib import Path
from typing import Callable

from laneshift.checkpoints import run_checkpoint
from laneshift.config import EnvConfig
from laneshift.progress import write
from laneshift.tools.studies.protocol_results import TEST_SEED
from laneshift.tools.studies.provenance import command_line, git_revision, write_json


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


def published_rates(checkpoint: Path, env: dict, test: dict, evals: dict[str, dict]) -> dict[str, dict]:
    """A published JSON's test rates per initial lane, each with the ``laneshift eval`` command that
    reproduces it."""
    return {lane: {"survival_rate": e["survival_rate"], "achievement_rate": e["achievement_rate"],
                   "episodes": e["episodes"], "survival_ci95": e.get("survival_ci95"),
                   "achievement_ci95": e.get("achievement_ci95"),
                   "command": eval_command(checkpoint, env, test["episodes_per_lane"], test["max_steps"], lane)}
            for lane, e in evals.items()}


def publish_final(run: dict, dest: Path, road: str, method: str, label: str,
                  tested: Callable[[Path], dict]) -> list[Path]:
    """One seed's final network as ``dest/<road>-<method>-seed<N>-final.safetensors`` and a ``.json``
    beside it: its provenance (this command, the training's command and revision, the resolved
    config) around ``tested(checkpoint)``, the protocol's own test table. The files written; none
    if the run's final network is gone (said on a line starting with ``label``)."""
    seed = run["seed"]
    final = run_checkpoint(run["run_dir"])
    if not final.is_file():
        write(f"{label}: publish: seed {seed}: {final} is gone; not published")
        return []
    dest.mkdir(parents=True, exist_ok=True)
    stem = f"{road}-{method}-seed{seed}-final"
    checkpoint = dest / f"{stem}.safetensors"
    shutil.copyfile(final, checkpoint)
    doc = {"checkpoint": checkpoint.name, "road": road, "method": method, "seed": seed,
           "command": command_line(), "cwd": os.getcwd(), "git": git_revision(),
           "trained_by": {"command": run.get("command"), "git": run.get("git")},
           "env_steps": run["env_steps"], "run_dir": run["run_dir"], **tested(checkpoint), "config": run["config"]}
    write_json(dest / f"{stem}.json", doc)
    write(f"{label}: published {checkpoint} and {stem}.json")
    return [checkpoint, dest / f"{stem}.json"]


def publish_run(run: dict, dest: Path, road: str, method: str) -> list[Path]:
    """One seed's final network as ``dest/<road>-<method>-seed<N>-final.safetensors`` with its
    provenance and test table beside it (``.json``), from the seed's record (``<method>-s<seed>.json``);
    allroads: the four roads pooled in ``lanes`` (no one command gives them) and per road in ``roads``,
    with each road's ``laneshift eval`` commands. The protocol calls it as each seed finishes, so a
    finished seed's network is published even if a later seed's run is stopped."""
    return publish_final(run, dest, road, method, "protocol", lambda checkpoint: {
        "test": _test_table(checkpoint, run), "validation": run["validation"]})


def _test_table(checkpoint: Path, run: dict) -> dict:
    """A published JSON's ``test``: the test episodes and their rates per initial lane (allroads:
    pooled, and per road), each with the ``laneshift eval`` command that reproduces it."""
    test, env = run["test"], run["config"]["env"]
    by_road = run.get("eval_by_road")
    if by_road is None:
        lanes = published_rates(checkpoint, env, test, run["eval"])
        roads = {}
    else:
        roads = {"roads": {r: published_rates(checkpoint, {**env, "road": r}, test, e) for r, e in by_road.items()}}
        lanes = {lane: {k: e.get(k) for k in ("survival_rate", "achievement_rate", "episodes", "survival_ci95",
                                              "achievement_ci95")} | {"pooled_over": list(by_road)}
                 for lane, e in run["eval"].items()}
    return {"episode_seed": test["episode_seed"], "episodes_per_lane": test["episodes_per_lane"],
            "max_steps": test["max_steps"], "lanes": lanes, **roads}
