"""The baseline a user would otherwise pick: stable-baselines3's DQN, one process, same env.

Optional dependency (``pip install -e ".[baselines]"``, pins stable-baselines3 2.9.2). The env,
its reward preset and observation are exactly the ones laneshift trains on; the network is the
same 256x256 MLP; every other hyperparameter is sb3's default, which is what a user starting
from the sb3 docs gets. Every ``--eval-every`` env steps the greedy policy is scored on the same
evaluation episodes as ``laneshift experiment checkpoints`` uses; the clock that is reported
counts training only (evaluation time is subtracted), so it compares with laneshift's
``elapsed_s``.

    laneshift experiment sb3 --scenario straight --env-steps 150000 --eval-every 25000 --out runs/sb3

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from laneshift.tools.argtypes import fraction, non_negative_int, positive_int
from laneshift.config import EnvConfig
from laneshift.actors.envs import make as make_env
from laneshift.tools.studies.evaluate import INITIAL_LANES, evaluate_lanes
from laneshift.progress import progress, write


def train_sb3(env_cfg: EnvConfig, env_steps: int, eval_every: int, eval_episodes: int, seed: int,
              eval_seed: int, stop_at_achievement: float | None = None, out: Path | None = None,
              show_progress: bool = False) -> dict:
    """``show_progress``: env steps (and each evaluation) as progress bars on stderr."""
    try:
        from stable_baselines3 import DQN
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.logger import Logger
    except ImportError as exc:
        raise SystemExit(f"needs stable-baselines3: pip install -e '.[baselines]' ({exc})")
    import numpy as np
    import torch

    torch.set_num_threads(1)
    model = DQN("MlpPolicy", make_env(env_cfg), seed=seed, verbose=0, buffer_size=100_000,
                policy_kwargs={"net_arch": [256, 256]})
    # A logger that writes nowhere: SB3's default makes an empty /tmp/SB3-<date> dir on every learn().
    model.set_logger(Logger(folder=None, output_formats=[]))
    curve: list[dict] = []
    eval_time = [0.0]
    started = time.monotonic()

    def greedy(obs: np.ndarray) -> int:
        return int(model.predict(obs, deterministic=True)[0])

    bar = progress(total=env_steps, desc="sb3 DQN", unit="step", disable=not show_progress)

    class Scores(BaseCallback):
        def _on_step(self) -> bool:
            bar.update()
            if self.num_timesteps % eval_every:
                return True
            t0 = time.monotonic()
            row = {"env_steps": self.num_timesteps,
                   "train_s": round(t0 - started - eval_time[0], 1)}
            for lane, r in evaluate_lanes(lambda _env: greedy, env_cfg, eval_episodes, eval_seed,
                                          progress=f"eval at {self.num_timesteps:,} steps" if show_progress
                                          else None).items():
                row[lane] = {k: r[k] for k in ("survival_rate", "achievement_rate", "return_mean") if k in r}
            eval_time[0] += time.monotonic() - t0
            curve.append(row)
            write(f"sb3: {row['env_steps']:,} steps, {row['train_s']:.0f} s training: "
                  + ", ".join(f"{lane} {row[lane]['survival_rate']:.0%}/{row[lane].get('achievement_rate', 0):.0%}"
                              for lane in INITIAL_LANES))
            reached = stop_at_achievement is not None and min(
                row[lane].get("achievement_rate", 0.0) for lane in INITIAL_LANES) >= stop_at_achievement
            return not reached

    try:
        model.learn(total_timesteps=env_steps, callback=Scores())
    finally:
        bar.close()
    result = {"library": "stable-baselines3", "algorithm": "DQN", "env": env_cfg.__dict__, "env_steps": env_steps,
              "seed": seed, "eval_episodes": eval_episodes, "eval_seed": eval_seed,
              "hyperparameters": {k: repr(getattr(model, k)) for k in (
                  "learning_rate", "buffer_size", "learning_starts", "batch_size", "gamma", "train_freq",
                  "gradient_steps", "target_update_interval", "exploration_fraction",
                  "exploration_initial_eps", "exploration_final_eps")},
              "net_arch": [256, 256], "curve": curve,
              "train_s": round(time.monotonic() - started - eval_time[0], 1)}
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        model.save(out / "sb3_dqn.zip")
        (out / "results.json").write_text(json.dumps(result, indent=2))
    return result


def _run(args: argparse.Namespace) -> int:
    env_cfg = EnvConfig(scenario=args.scenario)
    result = train_sb3(env_cfg, args.env_steps, args.eval_every, args.eval_episodes, args.seed, args.eval_seed,
                       args.stop_at_achievement, Path(args.out), show_progress=True)
    print(json.dumps(result) if args.json else f"sb3 DQN: {result['train_s']:.0f} s training; results in {args.out}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("sb3", help="stable-baselines3 DQN on the same env (single-process baseline)")
    p.add_argument("--scenario", default="straight", help="straight | merge | curve | roundabout | lka")
    p.add_argument("--env-steps", type=positive_int, default=150_000, help="env-step budget of the run")
    p.add_argument("--eval-every", type=positive_int, default=25_000, help="score the greedy policy every N env steps")
    p.add_argument("--eval-episodes", type=positive_int, default=50, help="greedy episodes per score and initial lane")
    p.add_argument("--eval-seed", type=non_negative_int, default=200_000, help="evaluation episode seeds")
    p.add_argument("--stop-at-achievement", type=fraction, default=None,
                   help="stop once both initial-lane settings reach this achievement rate (0 to 1)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="sb3's training seed")
    p.add_argument("--out", default="runs/sb3", help="where the model (sb3_dqn.zip) and results.json go")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.set_defaults(func=_run)
