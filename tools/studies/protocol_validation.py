"""The protocol's validation during training: the greedy evaluations a run logged every
``--validation-every`` env steps (``validation_curve``, from ``metrics.jsonl``), the first time
each reached an achievement level (``time_to_threshold``, ``THRESHOLDS``), its largest drop below
its running best (``stability_drop``) beside the drop evaluation noise alone would show
(``drop_noise``), and their table and figure (``validation_table``, ``plot_validation``:
``curves_validation.png``).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

from pathlib import Path

from laneshift.tools.studies.plots import plot_eval_curves
from laneshift.tools.studies.runs import metrics_records
from laneshift.tools.studies.stats import drop_noise_floor

#: The validation episodes of the greedy evaluation during training (``train.validation_seed``).
VALIDATION_SEED = 200_000
#: Validation achievement levels whose first crossing the table reports, per seed.
THRESHOLDS = (0.80, 0.95)


def time_to_threshold(curve: list[dict], threshold: float, key: str = "achievement_rate") -> dict | None:
    """The first validation evaluation whose ``key`` reached ``threshold``: its ``env_steps`` and
    ``elapsed_s`` (None if the record has none); None if no evaluation reached it."""
    for rec in curve:
        if rec.get(key) is not None and rec[key] >= threshold:
            return {"env_steps": rec["env_steps"], "elapsed_s": rec.get("elapsed_s")}
    return None


def stability_drop(curve: list[dict], target: float, key: str = "achievement_rate") -> float | None:
    """The largest drop of ``key`` below its running best, counted from the first evaluation that
    reached ``target`` on (0.0: it never fell below its best since); None if it never reached it."""
    values = [rec[key] for rec in curve if rec.get(key) is not None]
    start = next((i for i, v in enumerate(values) if v >= target), None)
    if start is None:
        return None
    best, drop = values[start], 0.0
    for v in values[start:]:
        best = max(best, v)
        drop = max(drop, best - v)
    return drop


def drop_noise(curve: list[dict], target: float, key: str = "achievement_rate") -> dict | None:
    """The largest drop (``stability_drop``) that a policy which never changed would show on these
    evaluations, from their few episodes alone: ``stats.drop_noise_floor`` at the run's last
    validation rate, with its episodes per evaluation and its number of evaluations (median, 90th
    percentile, share above 5 points). None if the run never reached ``target``. A measured drop
    near the median says nothing about the learner; one beyond the 90th percentile does."""
    values = [rec[key] for rec in curve if rec.get(key) is not None]
    episodes = curve[-1].get("episodes") if curve else None
    if not episodes or not any(v >= target for v in values):
        return None
    return drop_noise_floor(values[-1], int(episodes), len(values), target)


def validation_curve(run_dir: str | Path) -> list[dict]:
    """A run's greedy evaluations during training (``metrics.jsonl`` records of kind ``eval``), in
    order: ``env_steps``, ``elapsed_s`` (wall clock since the run's first metrics record: a resumed
    run's includes its pause), ``episodes``, ``survival_rate``, ``achievement_rate``. Empty without
    a metrics file."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        return []
    t0, curve = None, []
    for rec in metrics_records(path):
        if t0 is None and rec.get("time") is not None:
            t0 = rec["time"]
        if rec.get("kind") != "eval" or rec.get("env_steps") is None:
            continue
        elapsed = rec.get("elapsed_s")
        if elapsed is None and rec.get("time") is not None and t0 is not None:
            elapsed = round(rec["time"] - t0, 1)
        curve.append({"env_steps": rec["env_steps"], "elapsed_s": elapsed, "episodes": rec.get("episodes"),
                      "survival_rate": rec.get("survival_rate"), "achievement_rate": rec.get("achievement_rate")})
    return curve


def validation_table(results: dict) -> list[str]:
    """table.md's second part: per seed the time to the validation thresholds and the stability figure."""
    pct = "{:.1%}".format
    runs = results["methods"][results["method"]]["runs"]
    val, target = results["validation"], results["stability_target"]
    if not val.get("every"):
        return ["", "Validation during training: off (--validation-every 0)."]
    lines = ["", f"Validation during training: greedy, every {val['every']:,} env steps, {val['episodes']} "
                 f"episodes (episode seeds from {val['episode_seed']:,}), on the training's initial-lane setting. "
                 f"First evaluation at or above each achievement level (env steps, wall-clock seconds since the "
                 f"run's first metrics record); largest drop of the validation achievement below its running "
                 f"best after it first reached {pct(target)}, in percentage points, beside the drop that a policy "
                 f"which never changed shows on evaluations of this many episodes (at the seed's last validation "
                 f"rate: the median and 90th percentile of 20,000 simulated runs).", "",
             "| seed | " + " | ".join(f"{t:.0%} validation achievement" for t in results["thresholds"])
             + f" | largest drop after {pct(target)} | evaluation noise alone (median / 90th pct.) | evaluations |",
             "|---|" + "---|" * (len(results["thresholds"]) + 3)]
    for run in runs:
        s = results["per_seed"][str(run["seed"])]
        cells = []
        for t in results["thresholds"]:
            hit = s["reached"][f"{t:g}"]
            cells.append("not reached" if hit is None else f"{hit['env_steps']:,} steps"
                         + (f", {hit['elapsed_s']:,.0f} s" if hit.get("elapsed_s") is not None else ""))
        drop = "not reached" if s["largest_drop"] is None else f"{100 * s['largest_drop']:.1f} points"
        noise = s.get("drop_noise")
        floor = "-" if noise is None else f"{100 * noise['median']:.1f} / {100 * noise['p90']:.1f} points"
        note = " (resumed: its seconds include the pause)" if s.get("resumed") else ""
        lines.append(f"| {run['seed']}{note} | " + " | ".join(cells)
                     + f" | {drop} | {floor} | {s['validation_evaluations']} |")
    return lines


def plot_validation(results: dict, out_dir: Path) -> Path | None:
    """``curves_validation.png``: validation survival and achievement against env steps, the mean
    over seeds with a 95 % bootstrap band over seeds (``plots.plot_eval_curves``); None when
    no seed has two validation evaluations."""
    method = results["method"]
    runs = results["methods"][method]["runs"]
    return plot_eval_curves({**results, "scenario": results["road"]}, out_dir,
                            {f"{method}-s{r['seed']}": {"evals": r["validation"]["curve"]} for r in runs},
                            filename="curves_validation.png",
                            what=f"validation, episode seeds {results['validation']['episode_seed']:,}+")
