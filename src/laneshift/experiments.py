"""``laneshift experiment compare``: the paper's Table 2 comparison, reproducibly.

Every method is trained with the same budget and seeds through the real local system (Ray
workers, zenoh, replay-server and learner processes), then its final network is evaluated
greedily from both initial-lane settings; the baseline drivers are evaluated on the same episode
seeds. Rates are pooled over seeds (Wilson 95 % intervals over all evaluation episodes).

    laneshift experiment compare --scenario straight --methods none,retention,rehearsal,dqfd \\
        --seeds 0,1,2 --env-steps 150000 --eval-episodes 200 --out runs/exp-table2

Methods: ``none``, ``retention``, ``rehearsal`` (the paper), ``dqfd`` (beyond the paper: a
demo-only pre-training phase, then retention, with DQfD's large-margin loss on demo rows and
10-step returns), ``dqfd-bc`` (``dqfd`` plus a cross-entropy imitation loss on demo rows and a
dueling head). Writes ``results.json``, ``table.md`` and
``curves_episodes.png`` / ``curves_wallclock.png`` (moving-average return and episode length).
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import re
import time
from pathlib import Path
from typing import Any

import numpy as np

from .config import ConfigError, RunConfig, load_run_config
from .evaluate import INITIAL_LANES, evaluate_lanes, load_greedy_policy, wilson_ci95
from .progress import progress, write

# DQfD (Hester et al. 2018): pre-training on demos (20,000 updates), demos kept in the buffer
# (30 % of 300,000 items, i.e. about 300 scripted episodes), large-margin loss on demo rows,
# 10-step returns. Phase 2 explores from epsilon 0.3: the pre-trained network already drives.
_DQFD: dict[str, Any] = {
    "replay.demo_mode": "dqfd", "learner.margin_loss_weight": 1.0, "learner.n_step": 10,
    "learner.phase1_updates": 20_000, "replay.capacity": 300_000, "replay.demo_ratio": 0.3,
    "actor.phase2_epsilon_start": 0.3}

METHODS: dict[str, dict[str, Any]] = {
    "none": {"replay.demo_mode": "none"},
    "retention": {"replay.demo_mode": "retention"},
    "rehearsal": {"replay.demo_mode": "rehearsal"},
    "dqfd": _DQFD,
    # dqfd plus supervised imitation (cross-entropy on demo rows) and a dueling head: the two
    # changes that made the pre-trained network drive like the demonstrator (docs/RESULTS.md).
    "dqfd-bc": {**_DQFD, "learner.bc_loss_weight": 1.0, "learner.dueling": True},
}


def method_settings(method: str, option: str = "method") -> dict[str, Any]:
    """The named method's config overrides; an unknown name is refused naming ``option``."""
    if method not in METHODS:
        raise ConfigError(f"{option}: unknown {method!r} (known: {', '.join(METHODS)})")
    return METHODS[method]


def method_config(base: RunConfig, method: str, seed: int, run_dir: Path, env_steps: int,
                  user: dict[str, Any] | None = None) -> RunConfig:
    """The method's settings on top of ``base``; the user's ``--set`` values win over both."""
    overrides = {**method_settings(method, "--methods"), **(user or {}),
                 "train.run_dir": str(run_dir), "train.env_steps": env_steps,
                 "train.eval_episodes": 0, "train.seed": seed, "actor.seed": seed, "learner.seed": seed,
                 "replay.seed": seed, "transport.run_id": f"{method}-s{seed}"}
    return load_run_config(overrides=overrides, base=base)


class _TrainLog(io.StringIO):
    """A training run's console output, kept for its log file. The launcher's status lines
    (``steps 1,234/150,000 ...``) move ``bar`` (a line in another format just leaves it still)."""

    _STEPS = re.compile(r"steps\s+([\d,]+)/([\d,]+)")

    def __init__(self, bar):
        super().__init__()
        self.bar = bar

    def write(self, text: str) -> int:
        for m in self._STEPS.finditer(text):
            done = min(int(m.group(1).replace(",", "")), int(self.bar.total or 0))
            if done > self.bar.n:
                self.bar.update(done - self.bar.n)
        return super().write(text)


def train_logged(cfg: RunConfig, log_path: Path, label: str | None = None) -> None:
    """One real local training run, its console output kept in ``log_path``; raises if it failed.
    ``label``: show the run's env steps as a progress bar on stderr with this label."""
    from .deploy.local import train_local

    with progress(total=cfg.train.env_steps, desc=label or "", unit="step", leave=False,
                  disable=label is None) as bar:
        log = _TrainLog(bar)
        rc = train_local(cfg, out=log)
    log_path.write_text(log.getvalue())
    if rc != 0:
        raise RuntimeError(f"training run {cfg.train.run_dir} failed (rc {rc}); see {log_path}")


def pooled(evals: list[dict], key: str) -> dict:
    n = sum(e["episodes"] for e in evals)
    k = round(sum(e[key] * e["episodes"] for e in evals))
    lo, hi = wilson_ci95(k, n)
    return {"rate": k / n if n else 0.0, "ci95": [lo, hi], "episodes": n}


def run_compare(args: argparse.Namespace) -> dict:
    from .cli import parse_set

    user = parse_set(args.set)
    base = load_run_config(args.config, {"env.scenario": args.scenario, "actor.workers": args.workers, **user})
    methods, seeds = _names(args.methods), _seed_list(args.seeds)
    out_dir = Path(args.out).resolve()
    # Every run's config before the first run starts: a bad method, seed or --set fails now, not hours in.
    configs = {(m, s): method_config(base, m, s, out_dir / f"{m}-s{s}", args.env_steps, user)
               for m in methods for s in seeds}
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"scenario": args.scenario, "env_steps": args.env_steps, "seeds": seeds,
                               "eval_episodes": args.eval_episodes, "eval_max_steps": args.eval_max_steps,
                               "methods": {}, "baselines": {}}
    eval_seed = 100_000  # the same evaluation episodes for every method and baseline
    drivers = ("random", "keep-lane", "scripted") if args.baselines else ()
    overall = progress(total=len(configs) + len(drivers), desc="compare", unit="run")
    for method in methods:
        runs = []
        for seed in seeds:
            run_dir = out_dir / f"{method}-s{seed}"
            cfg = configs[(method, seed)]
            started = time.monotonic()
            train_logged(cfg, out_dir / f"{method}-s{seed}.log", label=f"train {method} seed {seed}")
            greedy = load_greedy_policy(run_dir / "checkpoints" / "final.safetensors")
            evals = evaluate_lanes(lambda env: greedy, dataclasses.replace(cfg.env, max_steps=args.eval_max_steps),
                                   args.eval_episodes, eval_seed, progress=f"eval {method} seed {seed}")
            runs.append({"seed": seed, "run_dir": str(run_dir), "wall_s": round(time.monotonic() - started, 1),
                         "eval": evals})
            write(f"experiment: {method} seed {seed}: " + ", ".join(
                f"{lane} survival {e['survival_rate']:.0%} achievement {e['achievement_rate']:.0%}"
                for lane, e in evals.items()))
            overall.update()
        results["methods"][method] = {"runs": runs, **{
            lane: {"survival": pooled([r["eval"][lane] for r in runs], "survival_rate"),
                   "achievement": pooled([r["eval"][lane] for r in runs], "achievement_rate")}
            for lane in INITIAL_LANES}}
    if args.baselines:
        from laneshift.actors.envs.demonstrator import KeepLaneDriver, ScriptedDriver

        def random_driver(env):
            env.action_space.seed(eval_seed)  # the random baseline's actions are reproducible too
            return lambda obs: env.action_space.sample()

        makers = {"random": random_driver, "keep-lane": KeepLaneDriver, "scripted": ScriptedDriver}
        n_base = args.eval_episodes * len(seeds)
        for name in drivers:
            evals = evaluate_lanes(makers[name], dataclasses.replace(base.env, max_steps=args.eval_max_steps), n_base,
                                   eval_seed, progress=f"baseline {name}")
            results["baselines"][name] = {lane: {"survival": pooled([e], "survival_rate"),
                                                 "achievement": pooled([e], "achievement_rate")}
                                          for lane, e in evals.items()}
            overall.update()
    overall.close()
    (out_dir / "results.json").write_text(json.dumps(results, indent=2))
    (out_dir / "table.md").write_text(render_table(results))
    plot_curves(results, out_dir)
    print(render_table(results))
    return results


def _names(text: str) -> list[str]:
    """``--methods``: comma separated, each one known."""
    methods = [m.strip() for m in text.split(",") if m.strip()]
    if not methods:
        raise ConfigError(f"--methods: name at least one of {', '.join(METHODS)}")
    for m in methods:
        method_settings(m, "--methods")
    return methods


def _seed_list(text: str) -> list[int]:
    """``--seeds``: comma-separated integers >= 0."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"--seeds: expected comma-separated integers >= 0, got {text!r}")
    return seeds


def render_table(results: dict) -> str:
    lines = [f"{results['scenario']}: {results['env_steps']:,} env steps per run, seeds {results['seeds']}, "
             f"{results['eval_max_steps']}-step greedy evaluation episodes "
             f"({results['eval_episodes']} per seed and initial lane; rates pooled, Wilson 95 % CI)", "",
             "| method | initial lane | survival | achievement |", "|---|---|---|---|"]
    rows = [(m, r) for m, r in results["methods"].items()] + [(f"{b} (baseline)", r)
                                                              for b, r in results["baselines"].items()]
    for name, r in rows:
        for lane in INITIAL_LANES:
            s, a = r[lane]["survival"], r[lane]["achievement"]
            lines.append(f"| {name} | {lane} | {s['rate']:.0%} [{s['ci95'][0]:.0%}, {s['ci95'][1]:.0%}] | "
                         f"{a['rate']:.0%} [{a['ci95'][0]:.0%}, {a['ci95'][1]:.0%}] |")
    return "\n".join(lines) + "\n"


def _episode_curves(run_dir: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wall-clock s, return, length) of every episode, in arrival order."""
    t, ret, length = [], [], []
    with open(Path(run_dir) / "metrics.jsonl") as f:
        for line in f:
            rec = json.loads(line)
            if rec.get("kind") == "episode":
                t.append(rec["time"])
                ret.append(rec["return"])
                length.append(rec["length"])
    t_arr = np.asarray(t)
    return (t_arr - t_arr[0] if len(t_arr) else t_arr), np.asarray(ret), np.asarray(length)


def _moving_average(x: np.ndarray, window: int) -> np.ndarray:
    if len(x) < window:
        return np.cumsum(x) / np.arange(1, len(x) + 1)
    return np.convolve(x, np.ones(window) / window, mode="valid")


def plot_curves(results: dict, out_dir: Path, window: int = 100) -> None:
    """Like the paper's figs 4/5: moving-average return and episode length, vs episodes and time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for axis in ("episodes", "wallclock"):
        fig, (ax_r, ax_l) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
        for method, r in results["methods"].items():
            for i, run in enumerate(r["runs"]):
                t, ret, length = _episode_curves(run["run_dir"])
                if len(ret) == 0:
                    continue
                ma_r, ma_l = _moving_average(ret, window), _moving_average(length.astype(float), window)
                x = np.arange(len(ret))[-len(ma_r):] if axis == "episodes" else t[-len(ma_r):]
                kw = {"color": f"C{list(results['methods']).index(method)}", "alpha": 0.8, "lw": 1.2,
                      "label": method if i == 0 else None}
                ax_r.plot(x, ma_r, **kw)
                ax_l.plot(x, ma_l, **kw)
        ax_r.set_ylabel(f"return ({window}-episode mean)")
        ax_l.set_ylabel("episode length (steps)")
        ax_l.set_xlabel("episodes" if axis == "episodes" else "wall-clock seconds")
        ax_r.legend()
        for ax in (ax_r, ax_l):
            ax.grid(alpha=0.3)
        fig.suptitle(f"{results['scenario']}: learning curves ({len(results['seeds'])} seeds, one line per run)")
        fig.tight_layout()
        fig.savefig(out_dir / f"curves_{axis}.png", dpi=100)
        plt.close(fig)


def register(subparsers: argparse._SubParsersAction) -> None:
    from .cli import add_set_arg, positive_int

    p = subparsers.add_parser("compare", help="train and evaluate methods x seeds (the paper's Table 2)")
    p.add_argument("--scenario", default="straight", help="straight | merge | curve | roundabout")
    p.add_argument("--methods", default="none,retention,rehearsal,dqfd", help=f"comma separated: {', '.join(METHODS)}")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated training seeds: one run per method and seed")
    p.add_argument("--env-steps", type=positive_int, default=150_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--eval-episodes", type=positive_int, default=200, help="greedy evaluation episodes per seed and initial lane")
    p.add_argument("--eval-max-steps", type=positive_int, default=300, help="evaluation episode length (paper: 300)")
    p.add_argument("--no-baselines", dest="baselines", action="store_false",
                   help="skip the random, keep-lane and scripted driver baselines")
    p.add_argument("--out", default="runs/experiment", help="where the runs, results.json, table.md and plots go")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_compare(a), 0)[1])
