"""The per-road parts of ``laneshift experiment protocol --scenario allroads``: one network for the
four roads, tested on each road as that road's own networks are.

Each road's test episodes are the single-road protocol's (episode seeds from 100,000, the same
count per initial lane, ``env.road`` pinning the road), so a row compares directly with the row of
the networks trained on that road alone, and the scripted driver and the human-like stand-in drive
the same episodes per road. ``merge_evals`` pools the four roads into the protocol's usual
per-initial-lane numbers (``results.json``'s ``methods`` and ``baselines``, which ``experiment
replot`` reads); ``road_results`` and ``render_road_table`` give the numbers and the table per road
and initial lane, with the target one network on all four roads is held to (``TARGET``: >= 95 %
survival and >= 90 % achievement on each road).

Room: the tools (studies). May import: anything in laneshift but the protocol's modules
(``laneshift.tools.studies.protocol*``, which import this one).
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import gymnasium as gym

from laneshift.config import EnvConfig
from laneshift.envspec import ALLROADS
from laneshift.tools.studies.evaluate import INITIAL_LANES, Policy, evaluate_lanes, wilson_ci95
from laneshift.tools.studies.table2 import (across_seeds, driven_rates, driver_cells, lane_stats, learned_cells,
                                            protocol_intro, rates_head)

#: The target for one network on all four roads, on each road and initial lane (docs/environments.md).
TARGET = {"survival": 0.95, "achievement": 0.90}
#: The pooled rows' name in the table.
ALL_FOUR = "all four"


def on_road(env_cfg: EnvConfig, road: str) -> EnvConfig:
    """``env_cfg`` with every episode on ``road``."""
    return dataclasses.replace(env_cfg, road=road)


def merge_evals(evals: list[dict]) -> dict:
    """One evaluation from several of disjoint episodes (the four roads'): episodes add up, rates
    and Wilson intervals over all of them; where every one has them (the human-like stand-in's have
    rates only), return and length weighted by episodes (the return's spread: the pooled standard
    deviation) and crashes summed by kind and start lane."""
    n = sum(e["episodes"] for e in evals)
    out: dict = {"episodes": n}
    if all("return_mean" in e for e in evals):
        mean = sum(e["return_mean"] * e["episodes"] for e in evals) / n
        second = sum((e["return_std"] ** 2 + e["return_mean"] ** 2) * e["episodes"] for e in evals) / n
        out.update(return_mean=mean, return_std=max(second - mean * mean, 0.0) ** 0.5,
                   length_mean=sum(e["length_mean"] * e["episodes"] for e in evals) / n)
    for metric in ("survival", "achievement"):
        k = round(sum(e[f"{metric}_rate"] * e["episodes"] for e in evals))
        out[f"{metric}_rate"], out[f"{metric}_ci95"] = k / n, wilson_ci95(k, n)
    if all("crashes" in e for e in evals):
        crashes: dict[str, dict[str, int]] = {}
        for e in evals:
            for kind, by_lane in e["crashes"].items():
                for lane, count in by_lane.items():
                    crashes.setdefault(kind, {})[lane] = crashes.get(kind, {}).get(lane, 0) + count
        out["crashes"] = crashes
    return out


def evaluate_roads(make_policy: Callable[[gym.Env], Policy], env_cfg: EnvConfig, episodes: int, seed: int,
                   progress: str | None = None) -> dict[str, dict[str, dict]]:
    """``{road: {initial lane: evaluation}}``: each road's own episodes (seeds ``seed`` ...), each
    initial-lane setting, as the single-road evaluation of that road."""
    return {road: evaluate_lanes(make_policy, on_road(env_cfg, road), episodes, seed,
                                 progress=None if progress is None else f"{progress}, {road}")
            for road in ALLROADS}


def pooled_roads(by_road: dict[str, dict[str, dict]]) -> dict[str, dict]:
    """``{initial lane: the four roads' evaluations merged}``."""
    return {lane: merge_evals([by_road[road][lane] for road in ALLROADS]) for lane in INITIAL_LANES}


def road_runs(runs: list[dict], road: str) -> list[dict]:
    """The seeds' records as if each had been tested on ``road`` alone (``eval`` = that road's)."""
    return [{**run, "eval": run["eval_by_road"][road]} for run in runs]


def road_results(runs: list[dict], drivers_by_road: dict[str, dict[str, dict]], method: str,
                 scripted_row: str) -> dict[str, dict]:
    """``results.json``'s ``roads``: per road the method's per-lane numbers (as ``methods``), the
    drivers' (as ``baselines``), whether the target is met and whether the learned mean is at or
    above the scripted driver."""
    out = {}
    for road in ALLROADS:
        stats = lane_stats(road_runs(runs, road))
        drivers = drivers_by_road[road]
        out[road] = {
            "methods": {method: stats},
            "baselines": driven_rates(drivers),
            "target_met": {lane: {m: stats[lane][m]["rate"] >= TARGET[m] for m in TARGET} for lane in INITIAL_LANES},
            "at_or_above_scripted": {lane: {m: stats[lane][m]["rate"] >= drivers[scripted_row][lane][f"{m}_rate"]
                                            for m in TARGET} for lane in INITIAL_LANES}}
    return out


def render_road_table(results: dict, driver_rows: tuple[str, str], intro: str | None = None) -> list[str]:
    """table.md's first part for allroads: one row per road and initial lane (then the four roads
    pooled): the learned rates beside the two drivers', the target and the scripted comparison
    (``intro``: the sentence above it, by default the protocol's)."""
    runs = results["methods"][results["method"]]["runs"]
    if intro is None:
        intro = protocol_intro(results, "allroads", network="one network for the four roads, ",
                               where="on each road its own ",
                               episodes_note=" with the road pinned: the single-road protocol's episodes, so a row "
                                             "compares with that road's own networks")
        intro += (f" Target: >= {TARGET['survival']:.0%} survival and >= {TARGET['achievement']:.0%} achievement "
                  f"on each road. '{ALL_FOUR}': the four roads' episodes pooled. The validation episodes below draw "
                  f"their road from their seed (seed % 4).")
    return [intro, "", *rates_head(("road", "initial lane"), (f"target {TARGET['survival']:.0%} / "
                                                              f"{TARGET['achievement']:.0%} met",
                                                              "learned mean at/above scripted")),
            *_road_rows(results, runs, driver_rows)]


def _road_rows(results: dict, runs: list[dict], driver_rows: tuple[str, str]) -> list[str]:
    """One table row per road and initial lane, then the four roads pooled."""
    lines = []
    sections = [(road, road_runs(runs, road), results["roads"][road]["baselines"]) for road in ALLROADS]
    sections.append((ALL_FOUR, runs, results["baselines"]))
    for road, road_view, base in sections:
        for lane in INITIAL_LANES:
            stats = {m: across_seeds(road_view, lane, f"{m}_rate") for m in TARGET}
            cells = learned_cells(list(stats.values())) + driver_cells(base, lane, driver_rows)
            met = ", ".join(f"{m} {'yes' if stats[m]['rate'] >= TARGET[m] else 'no'}" for m in TARGET)
            above = ", ".join(f"{m} {'yes' if stats[m]['rate'] >= base[driver_rows[0]][lane][m]['rate'] else 'no'}"
                              for m in TARGET)
            lines.append(f"| {road} | {lane} | " + " | ".join(cells) + f" | {met} | {above} |")
    return lines
