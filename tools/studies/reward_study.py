"""``laneshift experiment presets``: the paper's reward study (Table 1, figure 4).

Each reward condition 1-5 is trained on each of the merge, curve and roundabout scenarios
(100-step episodes, the paper's setting for this study) through the real local system, with the
condition's own exploration schedule (linear epsilon 1.0 -> 0.3 or 0.1, Table 1). The output is
the moving-average training return per condition, one panel per scenario, like figure 4, plus
each run's final greedy evaluation.

    laneshift experiment presets --scenarios merge,curve,roundabout --presets 1,2,3,4,5 \\
        --env-steps 30000 --out runs/exp-presets

Returns are only comparable within a condition: the conditions pay different rewards for the
same behaviour, which is why the table also gives survival and achievement.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from laneshift.checkpoints import run_checkpoint
from laneshift.tools.argtypes import add_set_arg, comma_list, non_negative_int, parse_set, positive_int
from laneshift.config import ConfigError, load_run_config
from laneshift.progress import progress, write


def preset_overrides(preset: int) -> dict[str, Any]:
    """The env's reward condition and Table 1's exploration schedule for it."""
    from laneshift.actors.envs.rewards import get_preset

    try:
        p = get_preset(preset)
    except ValueError as exc:  # an unknown condition
        raise ConfigError(f"--presets: {exc}") from None
    return {"env.reward_preset": preset, "actor.exploration": "linear", "actor.epsilon_start": p.epsilon_initial,
            "actor.epsilon_final": p.epsilon_final}


def run_presets(args: argparse.Namespace) -> dict:
    from laneshift.tools.studies.evaluate import evaluate_checkpoint
    from laneshift.tools.studies.runs import episode_curves, train_logged

    out_dir = Path(args.out).resolve()
    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    presets = args.presets
    if not scenarios:
        raise ConfigError(f"--scenarios: name at least one scenario, got {args.scenarios!r}")
    user = parse_set(args.set)
    # Every run's config before the first run starts: a bad scenario, condition or --set fails now.
    configs = {}
    for scenario in scenarios:
        for preset in presets:
            name = f"{scenario}-p{preset}"
            configs[name] = load_run_config(args.config, {
                "env.scenario": scenario, **preset_overrides(preset), "actor.workers": args.workers,
                "train.env_steps": args.env_steps, "train.run_dir": str(out_dir / name), "train.eval_episodes": 0,
                "train.seed": args.seed, "actor.seed": args.seed, "learner.seed": args.seed,
                "replay.seed": args.seed, "transport.run_id": name, **user})
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"env_steps": args.env_steps, "seed": args.seed, "runs": {}}
    returns_by_run: dict[str, np.ndarray] = {}  # training returns, read once for the table and the plot
    overall = progress(total=len(configs), desc="presets", unit="run")
    for scenario in scenarios:
        for preset in presets:
            name = f"{scenario}-p{preset}"
            run_dir = out_dir / name
            cfg = configs[name]
            started = time.monotonic()
            train_logged(cfg, out_dir / f"{name}.log", label=f"train {name}")
            _, returns, lengths = episode_curves(str(run_dir))
            returns_by_run[name] = returns
            ev = evaluate_checkpoint(run_checkpoint(run_dir), cfg.env,
                                     episodes=args.eval_episodes, seed=100_000, progress=f"eval {name}")
            tail = returns[-100:] if len(returns) else np.zeros(1)
            results["runs"][name] = {
                "scenario": scenario, "preset": preset, "run_dir": str(run_dir),
                "wall_s": round(time.monotonic() - started, 1), "episodes": int(len(returns)),
                "return_last100": float(np.mean(tail)),
                "length_last100": float(np.mean(lengths[-100:])) if len(lengths) else 0.0,
                "eval": {k: ev[k] for k in ("survival_rate", "achievement_rate", "return_mean") if k in ev}}
            r = results["runs"][name]
            write(f"presets: {name}: {r['episodes']} episodes, last-100 return {r['return_last100']:.1f}, "
                  f"greedy survival {r['eval']['survival_rate']:.0%} achievement {r['eval'].get('achievement_rate', 0):.0%}")
            overall.update()
    overall.close()
    (out_dir / "results.json").write_text(json.dumps(results, indent=2))
    (out_dir / "table.md").write_text(render(results))
    plot(returns_by_run, scenarios, presets, out_dir / "returns.png")
    print(render(results))
    return results


def render(results: dict) -> str:
    lines = [f"{results['env_steps']:,} env steps per run, seed {results['seed']}", "",
             "| scenario | condition | episodes | last-100 return | last-100 length | greedy survival | greedy achievement |",
             "|---|---|---|---|---|---|---|"]
    for r in results["runs"].values():
        lines.append(f"| {r['scenario']} | {r['preset']} | {r['episodes']:,} | {r['return_last100']:.1f} | "
                     f"{r['length_last100']:.0f} | {r['eval']['survival_rate']:.0%} | "
                     f"{r['eval'].get('achievement_rate', 0):.0%} |")
    return "\n".join(lines) + "\n"


def plot(returns_by_run: dict[str, np.ndarray], scenarios: list[str], presets: list[int], png: Path,
         window: int = 50) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from laneshift.tools.studies.plots import moving_average

    fig, axes = plt.subplots(1, len(scenarios), figsize=(5 * len(scenarios), 4), squeeze=False)
    for ax, scenario in zip(axes[0], scenarios):
        for preset in presets:
            returns = returns_by_run.get(f"{scenario}-p{preset}")
            if returns is not None and len(returns):
                ma = moving_average(returns, window)
                ax.plot(np.arange(len(returns))[-len(ma):], ma, label=f"condition {preset}", color=f"C{preset - 1}")
        ax.set_title(scenario)
        ax.set_xlabel("episodes")
        ax.set_ylabel(f"return ({window}-episode mean)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Reward conditions of Table 1 (figure 4): training return")
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("presets", help="reward conditions 1-5 on merge/curve/roundabout (figure 4)")
    p.add_argument("--scenarios", default="merge,curve,roundabout", help="comma-separated scenarios")
    p.add_argument("--presets", type=comma_list(positive_int, "reward conditions 1-5"), default=[1, 2, 3, 4, 5],
                   help="comma-separated reward conditions (Table 1)")
    p.add_argument("--env-steps", type=positive_int, default=30_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--eval-episodes", type=positive_int, default=50, help="greedy evaluation episodes of each run")
    p.add_argument("--seed", type=non_negative_int, default=0, help="training seed of every run")
    p.add_argument("--out", default="runs/exp-presets", help="where the runs, results.json, table.md and plot go")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_presets(a), 0)[1])
