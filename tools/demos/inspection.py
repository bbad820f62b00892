"""Summaries of a demo shard: sizes, returns, success rates, action histogram, return plot.

``summarize`` takes a loaded ``DemoShard`` or, cheaper, the verified per-episode data of
``read_verified`` (no flat copy of the observations). A human-like stand-in's shard shows its
label ("... not a person") and its reaction delay / action noise.

Imports: numpy, matplotlib (lazily, for the plot), the demos package.

Example::

    >>> summary = summarize(load_shard("runs/demos/straight"))          # doctest: +SKIP
    >>> summary = summarize(read_verified("runs/demos/straight"))       # doctest: +SKIP
    >>> print(format_summary(summary))                                   # doctest: +SKIP
    >>> plot_returns(summary, "runs/demos/straight_returns.png")         # doctest: +SKIP

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from laneshift.demos.outcomes import outcome_rates
from laneshift.demos.shard import DemoShard, ShardEpisodes


def summarize(source: DemoShard | ShardEpisodes) -> dict[str, Any]:
    """Plain-data (JSON-serialisable) summary of a loaded shard or of its verified episodes."""
    meta = source.metadata if isinstance(source, DemoShard) else source.meta
    if isinstance(source, DemoShard):
        lengths = np.bincount(source.episode_ids) if len(source) else np.zeros(0, np.int64)
        returns = np.bincount(source.episode_ids, weights=source.rewards.astype(np.float64))
        actions = source.actions
        terminated, truncated = int(source.terminations.sum()), int(source.truncations.sum())
    else:
        lengths = np.array([len(a) for a in source.actions], np.int64)
        returns = np.array([float(np.sum(r, dtype=np.float64)) for r in source.rewards])
        actions = np.concatenate(source.actions) if source.actions else np.zeros(0, np.int64)
        terminated = int(sum(t.sum() for t in source.terminations))
        truncated = int(sum(t.sum() for t in source.truncations))
    outcomes = meta.get("outcomes") or []
    rates = outcome_rates(outcomes) if len(outcomes) == len(returns) else {
        "survival_rate": None, "achievement_rate": None}
    n_actions = int(meta["n_actions"])
    return {
        "path": meta.get("path", str(getattr(source, "path", ""))),
        "env_id": meta["env_id"],
        "env_kwargs": meta.get("env_kwargs"),
        "observation": meta.get("observation"),
        "obs_shape": list(meta["obs_shape"]),
        "obs_dtype": meta["obs_dtype"],
        "obs_encoding": meta.get("obs_encoding"),
        "recorded_by": meta.get("recorded_by"),
        # The stand-in's parameters (None for people and the scripted expert).
        "stand_in": bool(meta.get("stand_in", False)),
        "reaction_steps": meta.get("reaction_steps"),
        "reaction_delay_s": meta.get("reaction_delay_s"),
        "action_noise": meta.get("action_noise"),
        "dataset_id": meta.get("dataset_id"),
        "info_keys": list(meta.get("info_keys") or []),
        "sha256": meta["sha256"],
        "episodes": int(len(returns)),
        "steps": int(lengths.sum()),
        "episode_length": _stats(lengths),
        "returns": _stats(returns),
        "episode_returns": [float(r) for r in returns],
        "terminated_episodes": terminated,
        "truncated_episodes": truncated,
        **rates,
        "n_actions": n_actions,
        "action_histogram": [int(c) for c in np.bincount(actions, minlength=n_actions)],
    }


def _stats(values: np.ndarray) -> dict[str, float | None]:
    if len(values) == 0:
        return {"mean": None, "min": None, "max": None}
    return {"mean": float(np.mean(values)), "min": float(np.min(values)),
            "max": float(np.max(values))}


def _pct(rate: float | None) -> str:
    return "n/a (the env's info does not report it)" if rate is None else f"{100 * rate:.1f} %"


def format_summary(summary: dict[str, Any]) -> str:
    """Human-readable multi-line text of :func:`summarize`'s result."""
    r, length = summary["returns"], summary["episode_length"]
    total = max(1, summary["steps"])
    lines = [
        f"demo shard   {summary['path']}",
        f"env          {summary['env_id']} {summary['env_kwargs']}",
        f"observation  {summary['observation']} {tuple(summary['obs_shape'])} "
        f"{summary['obs_dtype']} (stored as {summary['obs_encoding']})",
        f"recorded by  {summary['recorded_by']}",
    ]
    if summary.get("stand_in"):
        delay = summary.get("reaction_delay_s")
        lines.append(f"stand-in     reaction delay {summary['reaction_steps']} steps"
                     + (f" ({delay:g} s)" if delay is not None else "")
                     + f", action noise {summary['action_noise']:g}: NOT a person's driving")
    lines += [
        f"dataset id   {summary.get('dataset_id')}  (per-step infos: "
        f"{', '.join(summary.get('info_keys') or []) or 'none'})",
        f"sha256       {summary['sha256']}",
        f"episodes     {summary['episodes']}  ({summary['terminated_episodes']} terminated, "
        f"{summary['truncated_episodes']} truncated)",
        f"steps        {summary['steps']}  (episode length mean {length['mean']:.1f}, "
        f"min {length['min']:.0f}, max {length['max']:.0f})",
        f"return       mean {r['mean']:.3f}  min {r['min']:.3f}  max {r['max']:.3f}",
        f"survival     {_pct(summary['survival_rate'])}",
        f"achievement  {_pct(summary['achievement_rate'])}",
        "actions      index: count (share)",
    ]
    for index, count in enumerate(summary["action_histogram"]):
        bar = "#" * round(40 * count / total)
        lines.append(f"  {index:>3}: {count:>8} ({100 * count / total:5.1f} %) {bar}")
    return "\n".join(lines)


def plot_returns(summary: dict[str, Any], png: str | os.PathLike) -> Path:
    """Write a histogram of the episode returns to ``png`` (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")  # headless; never opens a window
    import matplotlib.pyplot as plt

    returns = np.asarray(summary["episode_returns"], dtype=np.float64)
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    try:
        ax.hist(returns, bins=min(30, max(1, len(returns))), color="#3b6ea8", edgecolor="white")
        ax.axvline(float(returns.mean()), color="black", linestyle="--",
                   label=f"mean {returns.mean():.2f}")
        ax.set_xlabel("episode return")
        ax.set_ylabel("episodes")
        who = "human-like stand-in" if summary.get("stand_in") else summary["recorded_by"]
        ax.set_title(f"{summary['env_id']} — {summary['episodes']} {who} episodes", fontsize=10)
        ax.legend()
        fig.tight_layout()
        fig.savefig(png)
    finally:
        plt.close(fig)
    return png
