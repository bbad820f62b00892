"""Greedy scores of every kept checkpoint of a run: the learning curve the final number hides.

A run trained with ``--set learner.keep_checkpoints=true`` keeps ``checkpoints/u<updates>.safetensors``
every ``learner.checkpoint_every`` updates, each with the env steps and seconds of training it
had behind it. This evaluates each one on the same greedy episodes, so the output answers "how
many env steps / how much wall time until X % achievement" (e.g. 80 %, as the protocol's table
reports) and shows
where the policy peaked, and picks the validation-selected checkpoint (:func:`select_best`).

    laneshift experiment checkpoints --run-dir runs/exp/dqfd-s0 --episodes 50 --copy-best best.safetensors

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from laneshift.checkpoints import checkpoints_dir, run_checkpoint
from laneshift.tools.argtypes import comma_list, non_negative_int, positive_int
from laneshift.config import ConfigError, EnvConfig, load_run_config
from laneshift.tools.studies.evaluate import INITIAL_LANES, evaluate_lanes, load_checkpoint_policy
from laneshift.progress import progress


def kept_checkpoints(run_dir: str | Path) -> list[Path]:
    """The run's periodic checkpoints, oldest first (then final.safetensors, if present)."""
    ckpts = sorted(checkpoints_dir(run_dir).glob("u*.safetensors"))
    final = run_checkpoint(run_dir)
    return ckpts + ([final] if final.exists() else [])


def evaluate_checkpoints(run_dir: str | Path, env: EnvConfig, episodes: int, seed: int,
                         initial_lanes: tuple[str, ...] = ("random",), show_progress: bool = False) -> list[dict]:
    """One row per kept checkpoint; ``show_progress``: progress bars on stderr."""
    rows = []
    for path in progress(kept_checkpoints(run_dir), desc="checkpoints", unit="checkpoint",
                         disable=not show_progress):
        ckpt = load_checkpoint_policy(path)
        meta, greedy = ckpt.meta, ckpt.greedy()
        row = {"checkpoint": path.name, "updates": int(meta.get("updates", 0)),
               "env_steps": int(meta.get("env_steps", 0)), "elapsed_s": float(meta.get("elapsed_s", 0.0))}
        for lane, r in evaluate_lanes(lambda _env: greedy, env, episodes, seed, initial_lanes,
                                      progress=f"eval {path.name}" if show_progress else None).items():
            row[lane] = {k: r[k] for k in ("survival_rate", "achievement_rate", "survival_ci95",
                                           "achievement_ci95", "return_mean") if k in r}  # LKA: no achievement
        rows.append(row)
    return rows


def first_reaching(rows: list[dict], lane: str, key: str, level: float) -> dict | None:
    """The first checkpoint whose ``key`` rate on ``lane`` is at least ``level``."""
    return next((r for r in rows if r[lane].get(key, -1.0) >= level), None)


def select_best(rows: list[dict], lanes: tuple[str, ...]) -> dict:
    """The validation-selected checkpoint: the highest achievement in its worst initial-lane
    setting, then the highest survival in its worst setting, then the highest mean return in its
    worst setting; the earliest on a full tie. LKA rows (no achievement) rank by survival, then
    by mean return.

    Select on the validation episodes (this command's default seeds) and report the chosen
    checkpoint on the test episodes (``laneshift eval --seed 100000``): selecting on the test
    episodes would overstate it.
    """
    def key(r: dict) -> tuple[float, float, float]:
        worst_ach = min(r[lane].get("achievement_rate", 0.0) for lane in lanes)
        worst_surv = min(r[lane]["survival_rate"] for lane in lanes)
        worst_ret = min(r[lane]["return_mean"] for lane in lanes)
        return (worst_ach, worst_surv, worst_ret)

    return max(rows, key=key)  # max keeps the first of equal keys: the earliest checkpoint


def render(rows: list[dict], lanes: tuple[str, ...]) -> str:
    head = "| checkpoint | updates | env steps | train s | " + " | ".join(
        f"{lane} survival | {lane} achievement" for lane in lanes) + " |"
    lines = [head, "|" + "---|" * (4 + 2 * len(lanes))]
    for r in rows:
        cells = [r["checkpoint"], f"{r['updates']:,}", f"{r['env_steps']:,}", f"{r['elapsed_s']:.0f}"]
        for lane in lanes:
            ach = r[lane].get("achievement_rate")
            cells += [f"{r[lane]['survival_rate']:.0%}", "-" if ach is None else f"{ach:.0%}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _run(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    if not (run_dir / "config.yaml").is_file():
        raise ConfigError(f"--run-dir {run_dir}: no run there (no config.yaml)")
    cfg = load_run_config(run_dir / "config.yaml")
    lanes = tuple(dict.fromkeys(args.initial_lanes))
    rows = evaluate_checkpoints(run_dir, cfg.env, args.episodes, args.seed, lanes, show_progress=True)
    if not rows:
        print(f"laneshift experiment checkpoints: no checkpoints in {run_dir / 'checkpoints'}", file=sys.stderr)
        return 1
    best = select_best(rows, lanes)
    out = {"run_dir": str(run_dir), "episodes": args.episodes, "seed": args.seed, "rows": rows,
           "first_80pct_achievement": {lane: first_reaching(rows, lane, "achievement_rate", 0.8) for lane in lanes},
           "best": best["checkpoint"]}
    if args.copy_best:
        dest = Path(args.copy_best)
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(run_dir / "checkpoints" / best["checkpoint"], dest)
        out["copied_best_to"] = str(dest)
    (run_dir / "checkpoint_curve.json").write_text(json.dumps(out, indent=2))
    if args.json:
        print(json.dumps(out))
    else:
        print(render(rows, lanes) + f"\nvalidation-selected: {best['checkpoint']} ({best['env_steps']:,} env steps, "
              f"{best['elapsed_s']:.0f} s of training)" + (f", copied to {args.copy_best}" if args.copy_best else ""))
    return 0


def _lane(text: str) -> str:
    if text not in INITIAL_LANES:
        raise ValueError(text)
    return text


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("checkpoints", help="greedy scores of every kept checkpoint of a run")
    p.add_argument("--run-dir", required=True, help="a run trained with --set learner.keep_checkpoints=true")
    p.add_argument("--episodes", type=positive_int, default=50, help="greedy episodes per checkpoint and initial lane")
    p.add_argument("--initial-lanes", type=comma_list(_lane, "initial lanes (random, non-target)"),
                   default=list(INITIAL_LANES), help="comma-separated initial-lane settings to score")
    p.add_argument("--seed", type=non_negative_int, default=200_000,
                   help="evaluation episode seeds (not the test seeds)")
    p.add_argument("--copy-best", metavar="PATH", help="copy the validation-selected checkpoint (see select_best) to PATH")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    p.set_defaults(func=_run)
