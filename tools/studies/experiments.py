"""``laneshift experiment compare``: the paper's Table 2 comparison, reproducibly.

Every method is trained with the same budget and seeds through the real local system (Ray
workers, zenoh, replay-server and learner processes), then its final network is evaluated
greedily from both initial-lane settings; the baseline drivers are evaluated on the same episode
seeds. A method's rate is the mean of its per-seed rates with a 95 % percentile bootstrap
interval over seeds (``laneshift.tools.studies.stats``); the rate pooled over all evaluation episodes
with its Wilson interval is kept beside it, labelled pooled (it treats the episodes of different
seeds as independent, so it understates the uncertainty).

    laneshift experiment compare --scenario straight --methods none,retention,rehearsal,dqfd \\
        --seeds 0,1,2 --env-steps 150000 --eval-episodes 200 --out runs/exp-table2
    laneshift experiment replot --results docs/results/table2-v2

Methods: ``none``, ``retention``, ``rehearsal`` (the paper), ``dqfd`` (beyond the paper: a
demo-only pre-training phase, then retention, with DQfD's large-margin loss on demo rows and
10-step returns), ``dqfd-bc`` (``dqfd`` plus a cross-entropy imitation loss on demo rows and a
dueling head). Writes ``results.json``, ``table.md``, ``table2.png`` (bars with across-seed
intervals), ``episodes.json`` (every run's per-episode data, so the curves can be redrawn once the
run dirs are gone), ``curves_env_steps.png`` / ``curves_episodes.png`` / ``curves_wallclock.png``
(moving-average return and episode length, mean over seeds with a 95 % bootstrap band; no env-step
figure for logs without env steps) and, for runs with ``train.eval_every``, ``curves_eval.png``
(greedy survival and achievement during training). ``replot`` redraws the table and figures of a
study from its ``results.json`` and ``episodes.json`` (or the runs' ``metrics.jsonl``).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import re
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from laneshift.tools.argtypes import add_set_arg, parse_set, positive_int
from laneshift.config import METHODS, ConfigError, EnvConfig, RunConfig, load_run_config, method_settings  # noqa: F401
from laneshift.tools.studies.evaluate import INITIAL_LANES, evaluate_lanes, load_greedy_policy, wilson_ci95
from laneshift.progress import progress, write
from laneshift.tools.studies.stats import RESAMPLES, bootstrap_ci, curves_on_grid

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


def train_logged(cfg: RunConfig, log_path: Path, label: str | None = None, resume: bool = False) -> None:
    """One real local training run, its console output kept in ``log_path``; raises if it failed.
    ``label``: show the run's env steps as a progress bar on stderr with this label. ``resume``:
    continue the unfinished run in ``cfg``'s run dir (``laneshift train --resume``), its output
    appended to the log."""
    from laneshift.deploy.local import train_local

    with progress(total=cfg.train.env_steps, desc=label or "", unit="step", leave=False,
                  disable=label is None) as bar:
        log = _TrainLog(bar)
        rc = train_local(cfg, out=log, resume=resume)
    with open(log_path, "a" if resume else "w") as f:
        f.write(log.getvalue())
    if rc != 0:
        raise RuntimeError(f"training run {cfg.train.run_dir} failed (rc {rc}); see {log_path}")


def pooled(evals: list[dict], key: str) -> dict:
    n = sum(e["episodes"] for e in evals)
    k = round(sum(e[key] * e["episodes"] for e in evals))
    lo, hi = wilson_ci95(k, n)
    return {"rate": k / n if n else 0.0, "ci95": [lo, hi], "episodes": n}


#: The stand-in's row name in results.json and the tables (it is not a person's driving).
HUMAN_LIKE_ROW = "human-like stand-in"


def human_like_lanes(env_cfg: EnvConfig, episodes: int, seed: int) -> dict[str, dict]:
    """The human-like stand-in (scripted driver, reaction delay 5 steps, action noise 0.07) on the
    test episodes of each initial-lane setting: the same seeds as every method and baseline."""
    from laneshift.tools.demos.humanlike import DEFAULT_ACTION_NOISE, DEFAULT_REACTION_STEPS, measure

    out = {}
    for lane in INITIAL_LANES:
        kwargs = dataclasses.replace(env_cfg, initial_lane=lane).env_kwargs()
        rates = measure(env_cfg.scenario, kwargs, episodes, seed, DEFAULT_REACTION_STEPS, DEFAULT_ACTION_NOISE)
        out[lane] = {"episodes": episodes, "survival_rate": rates["survival_rate"] or 0.0,
                     "achievement_rate": rates["achievement_rate"] or 0.0}
    return out


def run_compare(args: argparse.Namespace) -> dict:
    user = parse_set(args.set)
    base = load_run_config(args.config, {"env.scenario": args.scenario, "actor.workers": args.workers, **user})
    methods, seeds = _names(args.methods), seed_list(args.seeds)
    out_dir = Path(args.out).resolve()
    # Every run's config before the first run starts: a bad method, seed or --set fails now, not hours in.
    configs = {(m, s): method_config(base, m, s, out_dir / f"{m}-s{s}", args.env_steps, user)
               for m in methods for s in seeds}
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Any] = {"scenario": args.scenario, "env_steps": args.env_steps, "seeds": seeds,
                               "eval_episodes": args.eval_episodes, "eval_max_steps": args.eval_max_steps,
                               "methods": {}, "baselines": {}}
    eval_seed = 100_000  # the same evaluation episodes for every method and baseline
    # "human-like": the stand-in for the paper's human driver (laneshift.tools.demos.humanlike; not a person).
    drivers = ("random", "keep-lane", "scripted", "human-like") if args.baselines else ()
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
        results["methods"][method] = {"runs": runs, **lane_stats(runs)}
    if args.baselines:
        from laneshift.actors.envs.demonstrator import KeepLaneDriver, ScriptedDriver

        def random_driver(env):
            env.action_space.seed(eval_seed)  # the random baseline's actions are reproducible too
            return lambda obs: env.action_space.sample()

        makers = {"random": random_driver, "keep-lane": KeepLaneDriver, "scripted": ScriptedDriver}
        n_base = args.eval_episodes * len(seeds)
        for name in drivers:
            env_cfg = dataclasses.replace(base.env, max_steps=args.eval_max_steps)
            if name == "human-like":
                evals = human_like_lanes(env_cfg, n_base, eval_seed)
                name = HUMAN_LIKE_ROW
            else:
                evals = evaluate_lanes(makers[name], env_cfg, n_base, eval_seed, progress=f"baseline {name}")
            results["baselines"][name] = {lane: {"survival": pooled([e], "survival_rate"),
                                                 "achievement": pooled([e], "achievement_rate")}
                                          for lane, e in evals.items()}
            overall.update()
    overall.close()
    (out_dir / "results.json").write_text(json.dumps(results, indent=2))
    (out_dir / "table.md").write_text(render_table(results))
    plot_table2(results, out_dir)
    episodes, _ = collect_episodes(results, out_dir)
    if episodes:
        write_episodes(episodes, out_dir)
    plot_curves(results, out_dir, episodes=episodes)
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


def seed_list(text: str) -> list[int]:
    """``--seeds``: comma-separated integers >= 0."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise ConfigError(f"--seeds: expected comma-separated integers >= 0, got {text!r}")
    return seeds


def render_table(results: dict) -> str:
    """Table 2 as markdown: per method and initial lane, the mean over seeds of the per-seed rates
    with its 95 % bootstrap interval over seeds (the headline), then the rate pooled over all
    evaluation episodes with its Wilson interval (which treats episodes of different seeds as
    independent, so it is narrower than the data warrant). Baselines are one evaluation each:
    their rate, and the Wilson interval over its episodes."""
    lines = [f"{results['scenario']}: {results['env_steps']:,} env steps per run, seeds {results['seeds']}, "
             f"{results['eval_max_steps']}-step greedy evaluation episodes "
             f"({results['eval_episodes']} per seed and initial lane). Headline: mean of the per-seed rates, "
             f"95 % percentile bootstrap over seeds ({RESAMPLES:,} resamples; with two seeds it is the range of "
             f"their two rates, with one seed there is none). "
             f"Pooled: all episodes of all seeds as one sample, Wilson 95 % CI.", "",
             "| method | initial lane | seeds | survival | achievement | survival (pooled) | achievement (pooled) |",
             "|---|---|---|---|---|---|---|"]
    pct = "{:.0%}".format

    def cell(s: dict) -> str:
        shown = s.get("ci95") and s.get("seeds", 2) > 1  # one seed: no across-seed interval
        return pct(s["rate"]) + (f" [{pct(s['ci95'][0])}, {pct(s['ci95'][1])}]" if shown else "")

    for name, lane, seeds, s, a, ps, pa in table2_rows(results):
        lines.append(f"| {name} | {lane} | {seeds or '-'} | {cell(s)} | {cell(a)} | {cell(ps)} | {cell(pa)} |")
    return "\n".join(lines) + "\n"


def across_seeds(runs: list[dict], lane: str, key: str) -> dict:
    """``key`` (``survival_rate`` ...) of ``lane`` over the runs: the mean of the per-seed rates and
    its 95 % bootstrap interval over seeds (zero width with one seed: tables and plots then show
    none)."""
    per_seed = [float(r["eval"][lane][key]) for r in runs]
    return {"rate": float(np.mean(per_seed)), "ci95": list(bootstrap_ci(per_seed)), "seeds": len(per_seed),
            "per_seed": per_seed}


def table2_rows(results: dict) -> list[tuple[str, str, int, dict, dict, dict, dict]]:
    """(name, lane, seeds, survival, achievement, pooled survival, pooled achievement) for every
    method (stats across its seeds, computed from the per-seed evaluations, so older results.json
    files give the same) and baseline (one evaluation: seeds 0, its rate without an across-seed
    interval)."""
    rows = []
    for method, r in results["methods"].items():
        for lane in INITIAL_LANES:
            evals = [run["eval"][lane] for run in r["runs"]]
            rows.append((method, lane, len(r["runs"]),
                         across_seeds(r["runs"], lane, "survival_rate"), across_seeds(r["runs"], lane, "achievement_rate"),
                         pooled(evals, "survival_rate"), pooled(evals, "achievement_rate")))
    for name, r in results["baselines"].items():
        for lane in INITIAL_LANES:
            s, a = r[lane]["survival"], r[lane]["achievement"]
            rows.append((f"{name} (baseline)", lane, 0, {"rate": s["rate"], "ci95": None},
                         {"rate": a["rate"], "ci95": None}, s, a))
    return rows


def lane_stats(runs: list[dict]) -> dict:
    """A method's per-lane numbers for results.json: the across-seed headline and the pooled rate."""
    out = {}
    for lane in INITIAL_LANES:
        evals = [r["eval"][lane] for r in runs]
        out[lane] = {}
        for metric in ("survival", "achievement"):
            p = pooled(evals, f"{metric}_rate")
            out[lane][metric] = {**across_seeds(runs, lane, f"{metric}_rate"), "episodes": p["episodes"], "pooled": p}
    return out


# The paper's Table 2 (survival / achievement, %), as quoted in docs/RESULTS.md: drawn as marks on
# the straight-scenario bar chart. Method names are this project's (none = "no prior knowledge").
PAPER_TABLE2: dict[str, dict[str, tuple[float, float]]] = {
    "none": {"random": (53, 50), "non-target": (33, 29)},
    "retention": {"random": (49, 37), "non-target": (37, 10)},
    "rehearsal": {"random": (67, 66), "non-target": (51, 48)},
}
PAPER_HUMAN: dict[str, tuple[float, float]] = {"random": (50.7, 50.3)}


def plot_table2(results: dict, out_dir: Path) -> Path:
    """``table2.png``: survival and achievement per method and initial lane, bars at the mean of the
    per-seed rates with their 95 % bootstrap interval over seeds, each seed's rate as a dot;
    baselines as horizontal lines; for the straight scenario the paper's numbers as black marks
    (its human driver as a purple line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(results["methods"])
    paper = results.get("scenario") == "straight"
    fig, axes = plt.subplots(2, 2, figsize=(max(9.0, 3.0 + 2.6 * len(methods)), 7), sharey=True, squeeze=False)
    baseline_styles = ["--", "-.", ":", (0, (5, 1, 1, 1, 1, 1))]
    for col, lane in enumerate(INITIAL_LANES):
        for row, metric in enumerate(("survival", "achievement")):
            ax = axes[row][col]
            for i, method in enumerate(methods):
                st = across_seeds(results["methods"][method]["runs"], lane, f"{metric}_rate")
                ax.bar(i, st["rate"], width=0.6, color=f"C{i}", alpha=0.8)
                if st["seeds"] > 1:
                    ax.errorbar(i, st["rate"], yerr=[[max(0.0, st["rate"] - st["ci95"][0])], [max(0.0, st["ci95"][1] - st["rate"])]],
                                color="black", capsize=6, lw=1.5)
                n = len(st["per_seed"])
                ax.scatter(i + (np.linspace(-0.12, 0.12, n) if n > 1 else np.zeros(1)),
                           st["per_seed"], s=14, color="black", alpha=0.6, zorder=3,
                           label="one seed" if i == 0 else None)
                if paper and method in PAPER_TABLE2:
                    ax.plot([i - 0.38, i + 0.38], [PAPER_TABLE2[method][lane][row] / 100] * 2, color="black", lw=2.5,
                            label="paper (Table 2)" if method == next(m for m in methods if m in PAPER_TABLE2) else None)
            for j, (name, r) in enumerate(results["baselines"].items()):
                ax.axhline(r[lane][metric]["rate"], color="grey", lw=1.2, ls=baseline_styles[j % len(baseline_styles)],
                           label=f"{name} (baseline)")
            if paper and lane in PAPER_HUMAN:
                ax.axhline(PAPER_HUMAN[lane][row] / 100, color="tab:purple", lw=1.2, label="paper: human driver")
            ax.set_xticks(range(len(methods)), methods)
            ax.set_xlim(-0.6, len(methods) - 0.4)
            ax.set_ylim(0, 1.05)
            ax.set_title(f"{metric}, {lane} initial lane", fontsize=10)
            ax.grid(axis="y", alpha=0.3)
            if col == 0:
                ax.set_ylabel(f"{metric} rate")
    handles, labels = {}, []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(l, h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=min(len(handles), 6), fontsize=9)
    seeds = sorted({len(r["runs"]) for r in results["methods"].values()})
    what = ("one seed each (no interval)" if seeds == [1] else
            f"mean over {'/'.join(map(str, seeds))} seeds, 95 % bootstrap interval over seeds")
    fig.suptitle(f"{results['scenario']}: Table 2, {results['env_steps']:,} env steps per run; bars: {what}",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.07 if handles else 0, 1, 1))
    out = out_dir / "table2.png"
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


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


#: Per-episode data of a study's runs, kept next to its results.json (``write_episodes``) so that
#: ``laneshift experiment replot`` can redraw the curves once the run dirs are gone.
EPISODES_FILE = "episodes.json"


def metrics_records(path: Path) -> Iterator[dict]:
    """The records of a run's ``metrics.jsonl``, in order; a line cut short by a killed run is skipped."""
    with open(path) as f:
        for line in f:
            try:
                yield json.loads(line)
            except ValueError:
                continue


def run_episodes(run_dir: str | Path) -> dict | None:
    """A run's episodes from its ``metrics.jsonl``: ``time_s`` (since the run's first record, so a
    pre-training phase counts), ``env_steps`` (None if a record lacks it: logs written before
    episode records carried it), ``return`` and ``length``; None if the run has no metrics file."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        return None
    t0, t, steps, ret, length, evals = None, [], [], [], [], []
    for rec in metrics_records(path):
        t0 = rec.get("time") if t0 is None else t0
        if rec.get("kind") == "episode":
            t.append(rec["time"] - t0)
            steps.append(rec.get("env_steps"))
            ret.append(rec["return"])
            length.append(rec["length"])
        elif rec.get("kind") == "eval" and rec.get("env_steps") is not None:  # train.eval_every
            evals.append({k: rec[k] for k in EVAL_FIELDS})
    return {"time_s": t, "env_steps": None if None in steps else steps, "return": ret, "length": length,
            "evals": evals}


#: What a periodic greedy evaluation (``train.eval_every``) keeps in ``episodes.json``.
EVAL_FIELDS = ("env_steps", "episodes", "survival_rate", "achievement_rate", "return_mean", "length_mean")


def collect_episodes(results: dict, results_dir: Path) -> tuple[dict[str, dict], bool]:
    """Every run's episodes, keyed ``<method>-s<seed>``, from the study's ``episodes.json``, else
    the run's ``metrics.jsonl`` (at its recorded run dir, or a copy of the run dir next to
    results.json). Runs found nowhere are left out. Also returns whether any came from a run dir
    (then ``episodes.json`` is worth writing)."""
    kept_path = results_dir / EPISODES_FILE
    kept = json.loads(kept_path.read_text()).get("runs", {}) if kept_path.is_file() else {}
    out, from_runs = {}, False
    runs = [(m, run) for m, r in results["methods"].items() for run in r["runs"]]
    for method, run in progress(runs, desc="replot: read runs", unit="run", disable=not runs):
        key = f"{method}-s{run['seed']}"
        if key in kept:
            out[key] = kept[key]
            continue
        for place in (Path(run["run_dir"]), results_dir / Path(run["run_dir"]).name):
            episodes = run_episodes(place)
            if episodes is not None:
                out[key], from_runs = episodes, True
                break
    return out, from_runs


def write_episodes(episodes: dict[str, dict], out_dir: Path) -> Path:
    """``episodes.json``: the runs' per-episode data, rounded (ms, 1e-3 return) to stay small."""
    runs = {key: {"time_s": [round(x, 3) for x in e["time_s"]], "env_steps": e["env_steps"],
                  "return": [round(x, 3) for x in e["return"]], "length": e["length"],
                  "evals": e.get("evals", [])}
            for key, e in episodes.items()}
    out = out_dir / EPISODES_FILE
    out.write_text(json.dumps({"note": "per-episode training data of each run (<method>-s<seed>), from its "
                                       "metrics.jsonl; time_s since the run's first record", "runs": runs}))
    return out


def plot_curves(results: dict, out_dir: Path, window: int = 100, episodes: dict[str, dict] | None = None) -> list[Path]:
    """Like the paper's figs 4/5: moving-average return and episode length per method, the mean over
    seeds with a 95 % bootstrap band over seeds (:func:`laneshift.tools.studies.stats.curves_on_grid`:
    each seed's moving average interpolated onto a common grid over the range every seed covers),
    against env steps (``curves_env_steps.png``) and wall clock (``curves_wallclock.png``). Runs
    whose episodes lack env steps (older logs) give ``curves_episodes.png`` instead of the env-step
    figure. ``episodes``: per run (``<method>-s<seed>``), as :func:`collect_episodes` gives; by
    default read from the runs' dirs. Returns the files written (none without episodes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if episodes is None:
        episodes, _ = collect_episodes(results, out_dir)
    per_method = {m: [episodes[k] for run in r["runs"] if (k := f"{m}-s{run['seed']}") in episodes and
                      len(episodes[k]["return"]) > 0]
                  for m, r in results["methods"].items()}
    per_method = {m: runs for m, runs in per_method.items() if runs}
    if not per_method:
        return []
    with_steps = all(e["env_steps"] is not None for runs in per_method.values() for e in runs)
    # Episodes as in the paper's figures 4 and 5; env steps, the budget every method shares (an
    # episode lasts longer the better the policy); wall clock, what a user waits.
    axes = {**({"env_steps": "env steps"} if with_steps else {}), "episodes": "episodes",
            "wallclock": "wall-clock seconds (from the run's start)"}
    written = []
    for axis, xlabel in axes.items():
        fig, (ax_r, ax_l) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
        for method, runs in per_method.items():
            color = f"C{list(results['methods']).index(method)}"
            for ax, field in ((ax_r, "return"), (ax_l, "length")):
                xs, ys = [], []
                for e in runs:
                    y = _moving_average(np.asarray(e[field], dtype=float), window)
                    x = {"env_steps": e["env_steps"], "wallclock": e["time_s"],
                         "episodes": np.arange(1, len(e["return"]) + 1)}[axis]
                    xs.append(np.asarray(x, dtype=float)[-len(y):])  # each average at its window's last episode
                    ys.append(y)
                c = curves_on_grid(xs, ys)
                if len(c["x"]) == 0:
                    continue
                ax.plot(c["x"], c["mean"], color=color, lw=1.5,
                        label=f"{method} ({len(runs)} seed{'s' if len(runs) > 1 else ''})" if ax is ax_r else None)
                ax.fill_between(c["x"], c["lo"], c["hi"], color=color, alpha=0.2, lw=0)
        ax_r.set_ylabel(f"return ({window}-episode moving average)")
        ax_l.set_ylabel(f"episode length (steps, {window}-episode m. a.)")
        ax_l.set_xlabel(xlabel)
        ax_r.legend()
        for ax in (ax_r, ax_l):
            ax.grid(alpha=0.3)
        fig.suptitle(f"{results['scenario']}: learning curves, mean over seeds with 95 % bootstrap band over seeds\n"
                     f"(each seed on a common grid over the range all its method's seeds cover)", fontsize=10)
        fig.tight_layout()
        path = out_dir / f"curves_{axis}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path)
    eval_plot = plot_eval_curves(results, out_dir, episodes)
    return written + ([eval_plot] if eval_plot else [])


def plot_eval_curves(results: dict, out_dir: Path, episodes: dict[str, dict], filename: str = "curves_eval.png",
                     what: str = "greedy evaluation during training") -> Path | None:
    """``curves_eval.png`` (``filename``): the periodic greedy evaluations (``train.eval_every``) of
    each method, survival and achievement rate against env steps, mean over seeds with a 95 %
    bootstrap band over seeds. This, not the training return (which mixes in exploration), says
    whether the greedy policy has stopped improving. ``what``: the title's name for them. None when
    no run has two evaluations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per_method = {m: [evals for run in r["runs"]
                      if len(evals := episodes.get(f"{m}-s{run['seed']}", {}).get("evals") or []) >= 2]
                  for m, r in results["methods"].items()}
    per_method = {m: runs for m, runs in per_method.items() if runs}
    if not per_method:
        return None
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for method, runs in per_method.items():
        color = f"C{list(results['methods']).index(method)}"
        for ax, field in zip(axes, ("survival_rate", "achievement_rate")):
            c = curves_on_grid([np.asarray([e["env_steps"] for e in ev], dtype=float) for ev in runs],
                               [np.asarray([100.0 * e[field] for e in ev]) for ev in runs])
            if len(c["x"]) == 0:
                continue
            ax.plot(c["x"], c["mean"], color=color, lw=1.5,
                    label=f"{method} ({len(runs)} seed{'s' if len(runs) > 1 else ''})" if field == "survival_rate" else None)
            ax.fill_between(c["x"], c["lo"], c["hi"], color=color, alpha=0.2, lw=0)
    n = sorted({e["episodes"] for runs in per_method.values() for ev in runs for e in ev})
    axes[0].set_ylabel("greedy survival (%)")
    axes[1].set_ylabel("greedy achievement (%)")
    axes[1].set_xlabel("env steps")
    axes[0].legend()
    for ax in axes:
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{results['scenario']}: {what} ({'/'.join(map(str, n))} episodes "
                 f"each, the same episode seeds every time)\nmean over seeds, 95 % bootstrap band over seeds",
                 fontsize=10)
    fig.tight_layout()
    path = out_dir / filename
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _read_results(results_dir: Path, flag: str) -> dict:
    """A compare study's results.json, or exit with one line saying what is wrong with it."""
    path = results_dir / "results.json"
    if not path.is_file():
        raise SystemExit(f"{flag} {results_dir}: no results.json there (name a dir written by "
                         f"`laneshift experiment compare`)")
    try:
        results = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"{flag} {results_dir}: results.json is not readable JSON ({exc})") from None
    if not (isinstance(results, dict) and isinstance(results.get("methods"), dict)
            and isinstance(results.get("baselines"), dict) and "scenario" in results):
        raise SystemExit(f"{flag} {results_dir}: results.json is not from `laneshift experiment compare`")
    return results


#: What two studies must share for their runs to be one study's seeds.
SAME_STUDY = ("scenario", "env_steps", "eval_episodes", "eval_max_steps")


def merge_studies(results: dict, more: dict, where: str) -> None:
    """Add ``more``'s runs (other seeds of the same methods, budget and evaluation) to ``results``,
    and recompute each method's numbers over all its seeds; baselines ``results`` lacks are taken."""
    differ = [k for k in SAME_STUDY if results.get(k) != more.get(k)]
    if differ:
        raise SystemExit(f"--add {where}: not the same study ({', '.join(f'{k} {results.get(k)} vs {more.get(k)}' for k in differ)})")
    for method, body in more["methods"].items():
        runs = results["methods"].setdefault(method, {"runs": []})["runs"]
        seen = {r["seed"] for r in runs}
        twice = sorted(seen & {r["seed"] for r in body["runs"]})
        if twice:
            raise SystemExit(f"--add {where}: {method} seed(s) {twice} are in both studies")
        runs += body["runs"]
        runs.sort(key=lambda r: r["seed"])
        results["methods"][method] = {"runs": runs, **lane_stats(runs)}
    results["seeds"] = sorted({r["seed"] for body in results["methods"].values() for r in body["runs"]})
    for name, body in more["baselines"].items():
        results["baselines"].setdefault(name, body)


def run_replot(args: argparse.Namespace) -> int:
    """Redraw a study's table and figures from what it kept, without training (``--add``: with the
    seeds of other studies of the same setting merged in, written as this study's results.json)."""
    results_dir = Path(args.results)
    results = _read_results(results_dir, "--results")
    out_dir = Path(args.out) if args.out else results_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    episodes, from_runs = collect_episodes(results, results_dir)
    for extra in args.add or []:
        more = _read_results(Path(extra), "--add")
        merge_studies(results, more, extra)
        more_episodes, _ = collect_episodes(more, Path(extra))
        episodes.update(more_episodes)
        from_runs = from_runs or bool(more_episodes)
    if args.add:
        (out_dir / "results.json").write_text(json.dumps(results, indent=2))
        written.append(out_dir / "results.json")
    if results["methods"]:
        (out_dir / "table.md").write_text(render_table(results))
        written += [out_dir / "table.md", plot_table2(results, out_dir)]
    if episodes:
        if from_runs:
            written.append(write_episodes(episodes, out_dir))
        written += plot_curves(results, out_dir, args.window, episodes)
    else:
        write(f"replot: no per-episode data for any run ({EPISODES_FILE} or the runs' metrics.jsonl): "
              f"learning-curve figures left as they are")
    for p in written:
        write(f"replot: wrote {p}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("compare", help="train and evaluate methods x seeds (the paper's Table 2)")
    p.add_argument("--scenario", default="straight", help="straight | merge | curve | roundabout")
    p.add_argument("--methods", default="none,retention,rehearsal,dqfd", help=f"comma separated: {', '.join(METHODS)}")
    p.add_argument("--seeds", default="0,1,2", help="comma-separated training seeds: one run per method and seed")
    p.add_argument("--env-steps", type=positive_int, default=150_000, help="env-step budget of each training run")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--eval-episodes", type=positive_int, default=200, help="greedy evaluation episodes per seed and initial lane")
    p.add_argument("--eval-max-steps", type=positive_int, default=300, help="evaluation episode length (paper: 300)")
    p.add_argument("--no-baselines", dest="baselines", action="store_false",
                   help="skip the random, keep-lane, scripted and human-like stand-in driver baselines")
    p.add_argument("--out", default="runs/experiment", help="where the runs, results.json, table.md and plots go")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_compare(a), 0)[1])
    p = subparsers.add_parser("replot", help="redraw a compare study's table and figures from its kept data, "
                                             "without training")
    p.add_argument("--results", required=True, metavar="DIR",
                   help="a dir with the results.json of `laneshift experiment compare` (e.g. docs/results/table2-v2); "
                        f"curves need its {EPISODES_FILE} or the runs' metrics.jsonl")
    p.add_argument("--out", metavar="DIR", help="where table.md and the figures go (default: the --results dir)")
    p.add_argument("--window", type=positive_int, default=100, help="episodes in the curves' moving average")
    p.add_argument("--add", action="append", metavar="DIR",
                   help="another compare study of the same scenario, budget and evaluation whose seeds join "
                        "this one's (repeatable); the merged results.json is written to --out")
    p.set_defaults(func=run_replot)
