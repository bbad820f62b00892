"""The protocol's numbers and tables: the drivers on the test episodes (``drive_baselines``, kept
in ``baselines.json``; allroads: per road, ``road_baselines``), ``results.json`` (``summarise``, in
``experiment compare``'s layout) and ``table.md`` (``render_table``: the test rates beside the
drivers', then the validation table); with ``--final-validation-episodes``, the final networks and
the drivers on validation episodes too (``final_validation``), the numbers a choice between recipes
rests on; with ``--hold-test``, those alone (``held_test_summary``).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from laneshift.config import EnvConfig
from laneshift.progress import write
from laneshift.tools.studies import allroads
from laneshift.tools.studies.evaluate import INITIAL_LANES, evaluate_lanes
from laneshift.tools.studies.protocol_validation import (THRESHOLDS, drop_noise, stability_drop,
                                                        time_to_threshold, validation_table)
from laneshift.tools.studies.provenance import write_json
from laneshift.tools.studies.table2 import (HUMAN_LIKE_ROW, across_seeds, driven_rates, driver_cells,
                                            human_like_lanes, lane_stats, learned_cells, protocol_intro,
                                            rates_head)

#: The test episodes: episode i of each initial-lane setting is reset with seed TEST_SEED + i.
TEST_SEED = 100_000
#: The scripted driver's row name (``laneshift.actors.envs.demonstrator.ScriptedDriver``).
SCRIPTED_ROW = "scripted"
BASELINES_FILE = "baselines.json"


def drive_baselines(env_cfg: EnvConfig, episodes: int, out_dir: Path,
                    filename: str = BASELINES_FILE, episode_seed: int = TEST_SEED) -> dict[str, dict]:
    """The scripted driver and the human-like stand-in on the test episodes (per initial lane; other
    episodes from ``episode_seed``), kept in ``filename`` (default ``baselines.json``) and read back
    from there while they are of the same episodes."""
    from laneshift.actors.envs.demonstrator import ScriptedDriver

    env = dataclasses.asdict(env_cfg)
    from laneshift.replay_server.service import ENV_FIELDS_ADDED_LATER

    # The key of the files written before these fields existed, which stay valid: each at its default
    # drops out. They are the replay digest's later fields (one list, kept complete by its test) and
    # `road`; not `alongside_features`, which the key has carried since that field came.
    later = {"road": "", **{k: v for k, v in ENV_FIELDS_ADDED_LATER.items() if k != "alongside_features"}}
    for name, default in later.items():
        if env[name] == default:
            del env[name]
    key = json.loads(json.dumps({"env": env, "episodes": episodes, "episode_seed": episode_seed}))
    path = out_dir / filename
    if path.is_file():
        try:
            kept = json.loads(path.read_text())
        except ValueError:
            kept = {}
        if isinstance(kept, dict) and kept.get("key") == key:
            write(f"protocol: baselines: kept from {path}")
            return kept["drivers"]
        write(f"protocol: baselines: {path} is of other episodes; driving them again")
    label = "baseline scripted" + (f", {env_cfg.road}" if env_cfg.road else "")
    drivers = {SCRIPTED_ROW: evaluate_lanes(ScriptedDriver, env_cfg, episodes, episode_seed, progress=label),
               HUMAN_LIKE_ROW: human_like_lanes(env_cfg, episodes, episode_seed)}
    write_json(path, {"key": key, "drivers": drivers})
    return drivers


def road_baselines(env_cfg: EnvConfig, episodes: int, out_dir: Path, episode_seed: int = TEST_SEED,
                   prefix: str = "baselines") -> tuple[dict[str, dict], dict[str, dict]]:
    """allroads: the drivers on each road's test episodes (``<prefix>-<road>.json`` each), and
    pooled over the four roads as :func:`drive_baselines` returns them."""
    by_road = {road: drive_baselines(allroads.on_road(env_cfg, road), episodes, out_dir, f"{prefix}-{road}.json",
                                     episode_seed)
               for road in allroads.ALLROADS}
    pooled_drivers = {name: allroads.pooled_roads({road: by_road[road][name] for road in allroads.ALLROADS})
                      for name in (SCRIPTED_ROW, HUMAN_LIKE_ROW)}
    return pooled_drivers, by_road


def drivers_on(env_cfg: EnvConfig, episodes: int, out_dir: Path, episode_seed: int = TEST_SEED,
               prefix: str = "baselines") -> tuple[dict[str, dict], dict[str, dict] | None]:
    """The drivers on ``episodes`` episodes per initial lane from ``episode_seed``, kept in
    ``<prefix>.json`` (allroads: ``<prefix>-<road>.json`` per road), and for allroads per road too
    (None otherwise): what :func:`summarise` takes."""
    if env_cfg.is_allroads:
        return road_baselines(env_cfg, episodes, out_dir, episode_seed, prefix)
    return drive_baselines(env_cfg, episodes, out_dir, f"{prefix}.json", episode_seed), None


def summarise(args: argparse.Namespace, road: str, runs: list[dict], drivers: dict[str, dict],
              drivers_by_road: dict[str, dict] | None = None, episode_seed: int = TEST_SEED,
              episodes: int | None = None) -> dict:
    """results.json: the protocol's numbers, in ``experiment compare``'s layout (``methods``,
    ``baselines``) plus the per-seed validation measures and the comparison with the scripted driver;
    allroads (``drivers_by_road``): the four roads pooled there, and per road in ``roads``. The rates
    are of the test episodes unless ``episode_seed`` and ``episodes`` name others."""
    method = args.method
    per_seed = {}
    for run in runs:
        curve = run["validation"]["curve"]
        per_seed[str(run["seed"])] = {
            "reached": {f"{t:g}": time_to_threshold(curve, t) for t in THRESHOLDS},
            "largest_drop": stability_drop(curve, args.stability_target),
            "drop_noise": drop_noise(curve, args.stability_target),
            "validation_evaluations": len(curve), "resumed": run.get("resumed", False)}
    validation = runs[0]["validation"] if runs else {}
    return {"kind": "protocol", "road": road, "scenario": args.scenario, "method": method,
            "env_steps": args.env_steps, "seeds": [r["seed"] for r in runs],
            "eval_episodes": args.test_episodes, "eval_max_steps": args.eval_max_steps,
            **rates_summary(args, runs, drivers, drivers_by_road, episode_seed, episodes),
            "validation": {k: validation.get(k) for k in ("episode_seed", "every", "episodes")},
            "stability_target": args.stability_target, "thresholds": list(THRESHOLDS), "per_seed": per_seed}


def held_test_summary(args: argparse.Namespace, road: str, runs: list[dict], drivers: dict[str, dict],
                      drivers_by_road: dict[str, dict] | None) -> dict:
    """results.json of a study whose test is held (``--hold-test``): :func:`summarise`'s layout with
    the final networks' and the drivers' rates on the validation episodes in it, ``test`` naming those
    episodes and ``test_held`` saying so. A seed tested before is shown by its validation rates too."""
    kept = ("eval", "eval_by_road")
    views = [{**{k: v for k, v in run.items() if k not in kept},
              **{k: v for k, v in run["final_validation"].items() if k in kept}} for run in runs]
    first, episodes = (runs[0]["final_validation"][k] for k in ("episode_seed", "episodes_per_lane"))
    return {**summarise(args, road, views, drivers, drivers_by_road, first, episodes), "test_held": True}


def rates_summary(args: argparse.Namespace, runs: list[dict], drivers: dict[str, dict],
                  drivers_by_road: dict[str, dict] | None, episode_seed: int, episodes: int | None = None) -> dict:
    """The rates part of results.json: ``test`` (the episodes: ``episodes`` per lane from
    ``episode_seed``, by default the test's), ``methods`` (the runs' ``eval``), ``baselines``,
    ``at_or_above_scripted`` and, for allroads (``drivers_by_road``), ``roads``."""
    method = args.method
    body = {"runs": runs, **lane_stats(runs)}
    scripted = drivers[SCRIPTED_ROW]
    above = {lane: {m: body[lane][m]["rate"] >= scripted[lane][f"{m}_rate"] for m in ("survival", "achievement")}
             for lane in INITIAL_LANES}
    test = {"episode_seed": episode_seed, "episodes_per_lane": args.test_episodes if episodes is None else episodes,
            "max_steps": args.eval_max_steps}
    extra = {}
    if drivers_by_road is not None:
        test["roads"] = list(allroads.ALLROADS)
        extra["roads"] = allroads.road_results(runs, drivers_by_road, method, SCRIPTED_ROW)
    return {"test": test, **extra, "methods": {method: body}, "baselines": driven_rates(drivers),
            "at_or_above_scripted": above}


def render_table(results: dict) -> str:
    """table.md: the test rates per initial lane beside the baselines' (allroads: per road and initial
    lane), then the final networks' validation rates where measured, then per seed the time to the
    validation thresholds and the stability figure."""
    intro = held_test_intro(results) if results.get("test_held") else None
    if "roads" in results:
        lines = allroads.render_road_table(results, (SCRIPTED_ROW, HUMAN_LIKE_ROW), intro=intro)
    else:
        lines = rates_table(results, intro=intro)
    return "\n".join(lines + final_validation_table(results) + validation_table(results)) + "\n"


def held_test_intro(results: dict) -> str:
    """The sentence above a held-test study's table: its rates are the validation episodes', and the
    test episodes have not been driven."""
    val = results["test"]
    first, count = val["episode_seed"], val["episodes_per_lane"]
    where = "on each road its own " if "roads" in results else ""
    return (f"**{results['road']}, {results['method']}**: {results['env_steps']:,} env steps per run, seeds "
            f"{results['seeds']}, the final network of each run (no checkpoint selection), on the **validation "
            f"episodes** ({where}{count} per initial lane, episode seeds {first:,}-{first + count - 1:,}, "
            f"{val['max_steps']} steps each; the drivers drive them too). **Test held**: the test episodes have not "
            f"been driven; the same command without --hold-test drives them once the choice is made.")


def rates_table(results: dict, intro: str | None = None) -> list[str]:
    """table.md's first part: the test rates per initial lane beside the baselines' (``intro``: the
    sentence above it, by default the protocol's)."""
    runs = results["methods"][results["method"]]["runs"]
    lines = [protocol_intro(results, results["road"]) if intro is None else intro, "",
             *rates_head(("initial lane",), ("learned mean at/above scripted",))]
    base = results["baselines"]
    for lane in INITIAL_LANES:
        cells = learned_cells([across_seeds(runs, lane, f"{m}_rate") for m in ("survival", "achievement")])
        cells += driver_cells(base, lane, (SCRIPTED_ROW, HUMAN_LIKE_ROW))
        above = results["at_or_above_scripted"][lane]
        verdict = ", ".join(f"{m} {'yes' if above[m] else 'no'}" for m in ("survival", "achievement"))
        lines.append(f"| {lane} | " + " | ".join(cells) + f" | {verdict} |")
    return lines


def final_validation_results(args: argparse.Namespace, runs: list[dict], drivers: dict[str, dict],
                             drivers_by_road: dict[str, dict] | None, episode_seed: int) -> dict:
    """results.json's ``final_validation``: the final networks (each run's ``final_validation``) and
    the drivers on the validation episodes, in the layout of the test's rates (``test`` names the
    episodes; ``methods``' runs hold each seed's evaluations only)."""
    kept = ("eval", "eval_by_road")
    views = [{"seed": run["seed"], **{k: v for k, v in run["final_validation"].items() if k in kept}} for run in runs]
    return rates_summary(args, views, drivers, drivers_by_road, episode_seed,
                         runs[0]["final_validation"]["episodes_per_lane"])


def final_validation_table(results: dict) -> list[str]:
    """table.md's part on the final networks' validation rates (empty where not measured): the same
    columns as the test's, on the episodes that choices between recipes are made on."""
    val = results.get("final_validation")
    if not val:
        return []
    view = {**results, **val}
    first, count = val["test"]["episode_seed"], val["test"]["episodes_per_lane"]
    where = "on each road its own " if "roads" in val else ""
    intro = (f"The same final networks on the **validation episodes** ({where}{count} per initial lane, episode "
             f"seeds {first:,}-{first + count - 1:,}, {val['test']['max_steps']} steps each; the drivers drive them "
             f"too): the numbers a choice between recipes or settings rests on, never the test rates above.")
    if "roads" in val:
        lines = allroads.render_road_table(view, (SCRIPTED_ROW, HUMAN_LIKE_ROW), intro=intro)
    else:
        lines = rates_table(view, intro=intro)
    return ["", *lines]
