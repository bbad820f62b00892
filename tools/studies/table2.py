"""Table 2's numbers: a method's rates across seeds (the mean of the per-seed rates with a 95 %
bootstrap interval over seeds, ``laneshift.tools.studies.stats``) and pooled over every evaluation
episode (a Wilson interval), the baselines' rates, and the markdown table of a compare study.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from laneshift.config import EnvConfig
from laneshift.tools.studies.evaluate import INITIAL_LANES, wilson_ci95
from laneshift.tools.studies.stats import RESAMPLES, bootstrap_ci


def pooled(evals: list[dict], key: str) -> dict:
    n = sum(e["episodes"] for e in evals)
    k = round(sum(e[key] * e["episodes"] for e in evals))
    lo, hi = wilson_ci95(k, n)
    return {"rate": k / n if n else 0.0, "ci95": [lo, hi], "episodes": n}


def across_seeds(runs: list[dict], lane: str, key: str) -> dict:
    """``key`` (``survival_rate`` ...) of ``lane`` over the runs: the mean of the per-seed rates and
    its 95 % bootstrap interval over seeds (zero width with one seed: tables and plots then show
    none)."""
    per_seed = [float(r["eval"][lane][key]) for r in runs]
    return {"rate": float(np.mean(per_seed)), "ci95": list(bootstrap_ci(per_seed)), "seeds": len(per_seed),
            "per_seed": per_seed}


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
