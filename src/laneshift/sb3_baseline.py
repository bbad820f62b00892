"""The baseline a user would otherwise pick: stable-baselines3's DQN, one process, same env.

Optional dependency (``pip install -e ".[baselines]"``, pins stable-baselines3 2.9.2). The env,
its reward preset and observation are exactly the ones laneshift trains on; the network is the
same 256x256 MLP; every other hyperparameter is sb3's default, which is what a user starting
from the sb3 docs gets. Every ``--eval-every`` env steps the greedy policy is scored on the same
evaluation episodes as ``laneshift experiment checkpoints`` uses; the clock that is reported
counts training only (evaluation time is subtracted), so it compares with laneshift's
``elapsed_s``.

    laneshift experiment sb3 --scenario straight --env-steps 150000 --eval-every 25000 --out runs/sb3
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from .config import EnvConfig
from .envspec import make_env
from .evaluate import INITIAL_LANES, evaluate_lanes


def train_sb3(env_cfg: EnvConfig, env_steps: int, eval_every: int, eval_episodes: int, seed: int,
              eval_seed: int, stop_at_achievement: float | None = None, out: Path | None = None) -> dict:
    try:
        from stable_baselines3 import DQN
        from stable_baselines3.common.callbacks import BaseCallback
    except ImportError as exc:
        raise SystemExit(f"laneshift experiment sb3 needs stable-baselines3: pip install -e '.[baselines]' ({exc})")
    import numpy as np
    import torch

    torch.set_num_threads(1)
    model = DQN("MlpPolicy", make_env(env_cfg), seed=seed, verbose=0, buffer_size=100_000,
                policy_kwargs={"net_arch": [256, 256]})
    curve: list[dict] = []
    eval_time = [0.0]
    started = time.monotonic()

    def greedy(obs: np.ndarray) -> int:
        return int(model.predict(obs, deterministic=True)[0])

    class Scores(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every:
                return True
            t0 = time.monotonic()
            row = {"env_steps": self.num_timesteps,
                   "train_s": round(t0 - started - eval_time[0], 1)}
            for lane, r in evaluate_lanes(lambda _env: greedy, env_cfg, eval_episodes, eval_seed).items():
                row[lane] = {k: r[k] for k in ("survival_rate", "achievement_rate", "return_mean") if k in r}
            eval_time[0] += time.monotonic() - t0
            curve.append(row)
            print(f"sb3: {row['env_steps']:,} steps, {row['train_s']:.0f} s training: "
                  + ", ".join(f"{lane} {row[lane]['survival_rate']:.0%}/{row[lane].get('achievement_rate', 0):.0%}"
                              for lane in INITIAL_LANES), flush=True)
            reached = stop_at_achievement is not None and min(
                row[lane].get("achievement_rate", 0.0) for lane in INITIAL_LANES) >= stop_at_achievement
            return not reached

    model.learn(total_timesteps=env_steps, callback=Scores())
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
                       args.stop_at_achievement, Path(args.out))
    print(json.dumps(result) if args.json else f"sb3 DQN: {result['train_s']:.0f} s training; results in {args.out}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("sb3", help="stable-baselines3 DQN on the same env (single-process baseline)")
    p.add_argument("--scenario", default="straight")
    p.add_argument("--env-steps", type=int, default=150_000)
    p.add_argument("--eval-every", type=int, default=25_000)
    p.add_argument("--eval-episodes", type=int, default=50)
    p.add_argument("--eval-seed", type=int, default=200_000)
    p.add_argument("--stop-at-achievement", type=float, default=None,
                   help="stop once both initial-lane settings reach this achievement rate")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="runs/sb3")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_run)
