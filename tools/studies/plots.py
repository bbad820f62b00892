"""The figures of a compare study: ``table2.png`` (the rates per method and initial lane against the
paper's), the learning curves (``curves_env_steps.png``, ``curves_episodes.png``,
``curves_wallclock.png``) and the greedy evaluations during training (``curves_eval.png``).

Room: the tools (studies). May import: anything in laneshift, matplotlib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from laneshift.tools.studies.evaluate import INITIAL_LANES
from laneshift.tools.studies.runs import collect_episodes
from laneshift.tools.studies.stats import curves_on_grid
from laneshift.tools.studies.table2 import across_seeds


def evaluations_on_grid(runs: list[list[dict]], field: str) -> dict[str, np.ndarray]:
    """Several runs' greedy evaluations (each a list of ``{"env_steps", field: rate}``) as ``field`` in %
    against env steps on one grid: :func:`curves_on_grid`'s mean and band over the runs."""
    return curves_on_grid([np.asarray([e["env_steps"] for e in ev], dtype=float) for ev in runs],
                          [np.asarray([100.0 * e[field] for e in ev]) for ev in runs])


def draw_mean_band(ax, curve: dict[str, np.ndarray], color: str, label: str | None) -> None:
    """A :func:`curves_on_grid` result on ``ax``: the mean over runs as a line, the band shaded."""
    ax.plot(curve["x"], curve["mean"], color=color, lw=1.5, label=label)
    ax.fill_between(curve["x"], curve["lo"], curve["hi"], color=color, alpha=0.2, lw=0)


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    if len(x) < window:
        return np.cumsum(x) / np.arange(1, len(x) + 1)
    return np.convolve(x, np.ones(window) / window, mode="valid")


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
                    y = moving_average(np.asarray(e[field], dtype=float), window)
                    x = {"env_steps": e["env_steps"], "wallclock": e["time_s"],
                         "episodes": np.arange(1, len(e["return"]) + 1)}[axis]
                    xs.append(np.asarray(x, dtype=float)[-len(y):])  # each average at its window's last episode
                    ys.append(y)
                c = curves_on_grid(xs, ys)
                if len(c["x"]) == 0:
                    continue
                draw_mean_band(ax, c, color,
                               f"{method} ({len(runs)} seed{'s' if len(runs) > 1 else ''})" if ax is ax_r else None)
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
            c = evaluations_on_grid(runs, field)
            if len(c["x"]) == 0:
                continue
            draw_mean_band(ax, c, color,
                           f"{method} ({len(runs)} seed{'s' if len(runs) > 1 else ''})" if field == "survival_rate"
                           else None)
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
