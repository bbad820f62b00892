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


def driven_rates(drivers: dict[str, dict]) -> dict[str, dict]:
    """``results.json``'s ``baselines`` from the drivers' evaluations (``{name: {initial lane:
    evaluation}}``): per driver and initial lane, the survival and achievement rates of its one
    evaluation, each with the Wilson interval over its episodes."""
    return {name: {lane: {"survival": pooled([e], "survival_rate"), "achievement": pooled([e], "achievement_rate")}
                   for lane, e in evals.items()}
            for name, evals in drivers.items()}


def protocol_intro(results: dict, title: str, network: str = "", where: str = "",
                   episodes_note: str = ", never used for any choice") -> str:
    """The sentence above a protocol table (``title``: the road or allroads): the runs (``network``
    says which), the test episodes (``where`` and ``episodes_note`` say whose) and how the method's
    rates are shown."""
    test, seeds = results["test"], len(results["methods"][results["method"]]["runs"])
    first, count = test["episode_seed"], test["episodes_per_lane"]
    return (f"**{title}, {results['method']}**: {network}{results['env_steps']:,} env steps per run, seeds "
            f"{results['seeds']}, the final network of each run (no checkpoint selection). Test: {where}{count} greedy "
            f"episodes per initial lane (episode seeds {first:,}-{first + count - 1:,}{episodes_note}), "
            f"{test['max_steps']} steps each; the baselines drive the same episodes. Learned: mean of the per-seed rates"
            + (f" [95 % percentile bootstrap over seeds, {RESAMPLES:,} resamples]" if seeds > 1
               else " (one seed: no interval)") + ", then each seed's rate.")


def rates_head(before: tuple[str, ...], after: tuple[str, ...]) -> list[str]:
    """A protocol table's header row and rule: the ``before`` columns, the method's and the two
    drivers' rates (``learned_cells``, ``driver_cells``), the ``after`` columns."""
    columns = [*before, "survival", "achievement", "survival per seed", "achievement per seed",
               "scripted driver (survival / achievement)", "human-like stand-in (survival / achievement)", *after]
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def learned_cells(stats: list[dict]) -> list[str]:
    """The protocol tables' cells of a method's rates, from ``across_seeds`` of survival and
    achievement: each mean (with its interval over several seeds), then each one's per-seed rates."""
    pct = "{:.1%}".format
    means = [pct(st["rate"]) + (f" [{pct(st['ci95'][0])}, {pct(st['ci95'][1])}]" if st["seeds"] > 1 else "")
             for st in stats]
    return means + [", ".join(pct(x) for x in st["per_seed"]) for st in stats]


def driver_cells(baselines: dict, lane: str, names: tuple[str, ...]) -> list[str]:
    """The protocol tables' cells of the drivers ``names`` on ``lane``: survival / achievement."""
    pct = "{:.1%}".format
    return [f"{pct(baselines[name][lane]['survival']['rate'])} / {pct(baselines[name][lane]['achievement']['rate'])}"
            for name in names]


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
