"""``laneshift experiment paper``: the paper's question (which way of giving demonstrations wins)
answered on a learner that converges.

The paper's three modes (``none``, ``retention``, ``rehearsal``) and the DQfD-style mode, each on
the same learner (dqfd-bc-anneal's: 10-step returns, a dueling head, the step size annealed, an
average of the online weights handed out, exploration ending at 1 %; the ``*-anneal`` presets of
``laneshift.config.METHODS``), with the same env-step budget, seeds and demo shard. Every mode is
one ``experiment protocol`` (train the seeds with validation evaluations, test the final networks
on episode seeds from 100,000, the scripted driver and the human-like stand-in on the same
episodes), so a study is resumable the same way: the same command again skips what is done.

    laneshift experiment paper --scenario straight --demonstrator human-like --seeds 0,1,2,3,4 \\
        --env-steps 150000 --out runs/paper/straight-human-like

The demo shard is driven once per study (``--demonstrator``: the scripted driver, or the human-like
stand-in at about 60 / 52 %, near the paper's person) into ``<out>/demos`` and given to every demo
mode. Writes ``<out>/<mode>/`` (each mode's protocol), ``results.json`` (every mode's runs in
``experiment compare``'s layout, so ``experiment replot`` reads it), ``table.md`` (Table 2's rows
with intervals over seeds, the paper's numbers beside them, then the answer: which mode wins and by
how much, and whether retention declines after a peak), ``curves_episodes.png`` (figure 5: return
and episode length against episodes, mean over seeds with a bootstrap band), ``curves_env_steps.png``,
``curves_wallclock.png`` and ``curves_eval.png`` (greedy validation survival and achievement against
env steps), ``episodes.json`` (the curves' data, for ``experiment replot``).

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from laneshift.tools.argtypes import add_set_arg, fraction, non_negative_int, parse_set, positive_int
from laneshift.config import ConfigError, load_run_config, method_settings
from laneshift.progress import write
from laneshift.tools.studies import protocol
from laneshift.tools.studies.evaluate import INITIAL_LANES
from laneshift.tools.argtypes import seed_list
from laneshift.tools.studies.plots import PAPER_TABLE2, plot_curves  # the paper's Table 2 (straight road, frames)
from laneshift.tools.studies.provenance import command_line, write_json
from laneshift.tools.studies.runs import collect_episodes, write_episodes
from laneshift.tools.studies.table2 import HUMAN_LIKE_ROW, across_seeds
from laneshift.tools.studies.stats import RESAMPLES, SEED

#: The study's rows: the paper's three modes and the DQfD-style one, each on the annealed learner.
MODES: dict[str, str] = {"none": "none-anneal", "retention": "retention-anneal",
                         "rehearsal": "rehearsal-anneal", "dqfd": "dqfd-bc-anneal"}
DEMONSTRATORS = ("scripted", "human-like")
#: The episode seeds of the demo shard: apart from training (actor seeds), test (100,000+) and
#: validation (200,000+) episodes.
DEMO_SEED = 10_000
#: A human-like episode can end early in a crash: the shard is driven this much larger than the
#: largest demo region needs at full-length episodes.
DEMO_MARGIN = 1.5


def demo_episodes_needed(cfgs: list, episodes: int) -> int:
    """``--demo-episodes``, else enough full-length-or-shorter episodes for the largest demo region
    among the modes (``replay.demo_ratio`` of ``replay.capacity`` for a mode that keeps its demos)."""
    if episodes:
        return episodes
    need = max([c.replay.capacity * c.replay.demo_ratio for c in cfgs if c.replay.retains_demos] or [2_000])
    horizon = cfgs[0].env.max_steps
    if not horizon:  # 0: the scenario's own episode length
        from laneshift.actors.envs import make as make_env

        probe = make_env(cfgs[0].env)
        horizon = getattr(probe.unwrapped, "max_steps", None) or 100
        probe.close()
    return max(20, math.ceil(DEMO_MARGIN * need / horizon))


def ensure_shard(env_cfg, demonstrator: str, episodes: int, out_dir: Path) -> Path:
    """The study's demo shard, driven once (``<out>/demos/<scenario>-<driver>-<N>ep``) and kept."""
    from laneshift.tools.demos.generate import generate_shard

    path = out_dir / "demos" / f"{env_cfg.scenario}-{demonstrator}-{episodes}ep"
    if any(path.glob("**/metadata.json")):
        write(f"paper: demo shard kept from {path}")
        return path
    if path.exists():  # a shard cut short by a stopped study: drive it again
        import shutil

        shutil.rmtree(path)
    write(f"paper: driving the demo shard ({episodes} {demonstrator} episodes) into {path}")
    generate_shard(path, env_id_or_scenario=env_cfg.scenario, env_kwargs=env_cfg.env_kwargs(), episodes=episodes,
                   seed=DEMO_SEED, policy=demonstrator, progress=f"demos {demonstrator}")
    return path


def protocol_args(args: argparse.Namespace, mode: str, shard: Path | None) -> argparse.Namespace:
    """The ``experiment protocol`` command line of one mode of the study."""
    extra = [f"replay.demo_paths={shard}"] if shard is not None else []
    return argparse.Namespace(
        scenario=args.scenario, method=MODES[mode], seeds=args.seeds, env_steps=args.env_steps, workers=args.workers,
        test_episodes=args.test_episodes, eval_max_steps=args.eval_max_steps, validation_every=args.validation_every,
        validation_episodes=args.validation_episodes, final_validation_episodes=0,
        final_validation_seed=protocol.VALIDATION_SEED, hold_test=False, stability_target=args.stability_target,
        out=str(Path(args.out) / mode), publish=None, road=None, config=args.config, set=list(args.set or []) + extra,
        baselines_dir=str(args.out))  # the modes share one test set: the drivers drive it once per study


def difference_ci(a: list[float], b: list[float], resamples: int = RESAMPLES, seed: int = SEED) -> tuple[float, float]:
    """95 % percentile bootstrap interval of mean(a) - mean(b), each mode's seeds resampled on their own."""
    rng = np.random.default_rng(seed)
    xa, xb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ma = xa[rng.integers(0, len(xa), size=(resamples, len(xa)))].mean(axis=1)
    mb = xb[rng.integers(0, len(xb), size=(resamples, len(xb)))].mean(axis=1)
    lo, hi = np.quantile(ma - mb, [0.025, 0.975])
    return float(lo), float(hi)


def peak_decline(curve: list[dict], key: str = "achievement_rate") -> dict | None:
    """A validation curve's best value, where it was, its last value and the fall from the best
    to the last; None with fewer than two evaluations."""
    values = [(rec["env_steps"], rec[key]) for rec in curve if rec.get(key) is not None]
    if len(values) < 2:
        return None
    best_at, best = max(values, key=lambda v: v[1])
    return {"best": best, "best_at": best_at, "last": values[-1][1], "decline": best - values[-1][1]}


def answer(results: dict) -> list[str]:
    """The plain answer, from the numbers: per initial lane, the mode with the highest mean test
    achievement and its margin over the next (with the interval of the difference); then whether
    retention's validation achievement declined after a peak."""
    pct = "{:.1%}".format
    modes = results["modes"]
    lines = []
    for lane in INITIAL_LANES:
        ach = {m: across_seeds(modes[m]["runs"], lane, "achievement_rate") for m in modes}
        order = sorted(ach, key=lambda m: ach[m]["rate"], reverse=True)
        best = order[0]
        tied = [m for m in order if ach[m]["rate"] == ach[best]["rate"]]
        if len(tied) > 1:
            lines.append(f"- **{lane} initial lane**: no winner: {', '.join(tied)} tie at {pct(ach[best]['rate'])} "
                         f"achievement. Order: " + " > ".join(f"{m} {pct(ach[m]['rate'])}" for m in order) + ".")
            continue
        text = f"- **{lane} initial lane**: {best} wins with {pct(ach[best]['rate'])} achievement"
        if len(order) > 1:
            second = order[1]
            lo, hi = difference_ci(ach[best]["per_seed"], ach[second]["per_seed"])
            margin = ach[best]["rate"] - ach[second]["rate"]
            clear = "an interval that excludes 0: a difference the seeds support" if lo > 0 else \
                "an interval that includes 0: the seeds cannot tell these two apart"
            text += (f", {100 * margin:.1f} points above {second} ({pct(ach[second]['rate'])}); the difference's "
                     f"95 % bootstrap interval over seeds is [{100 * lo:.1f}, {100 * hi:.1f}] points, {clear}")
        text += ". Order: " + " > ".join(f"{m} {pct(ach[m]['rate'])}" for m in order) + "."
        lines.append(text)
    if "retention" in modes:
        falls = [(run["seed"], peak_decline(run["validation"]["curve"])) for run in modes["retention"]["runs"]]
        falls = [(s, f) for s, f in falls if f is not None]
        if falls:
            mean_fall = float(np.mean([f["decline"] for _, f in falls]))
            per = ", ".join(f"seed {s}: best {pct(f['best'])} at {f['best_at']:,} steps, last {pct(f['last'])}"
                            for s, f in falls)
            others = {m: float(np.mean([f["decline"] for run in modes[m]["runs"]
                                        if (f := peak_decline(run["validation"]["curve"])) is not None] or [0.0]))
                      for m in modes if m != "retention"}
            lines.append(f"- **Retention's decline after a peak** (validation achievement, best to last "
                         f"evaluation): {100 * mean_fall:.1f} points on average ({per}); the other modes fall "
                         + ", ".join(f"{m} {100 * v:.1f}" for m, v in others.items()) + " points.")
    return lines


def render_table(results: dict) -> str:
    """table.md: Table 2's rows (mean over seeds [bootstrap interval], then per seed), the paper's
    numbers beside the vector study's, the two drivers on the same episodes, then the answer."""
    pct = "{:.1%}".format
    first = next(iter(results["modes"].values()))
    test = first["test"]
    seeds = results["seeds"]
    lines = [f"**{results['scenario']}, demo shard of the {results['demonstrator']} driver** "
             f"({results['demo_episodes']:,} episodes, episode seeds from {DEMO_SEED:,}): "
             f"{results['env_steps']:,} env steps per run, seeds {seeds}, the final network of each run. Test: "
             f"{test['episodes_per_lane']} greedy episodes per initial lane (episode seeds {test['episode_seed']:,}+, "
             f"never used for any choice), {test['max_steps']} steps each. Mean of the per-seed rates "
             f"[95 % percentile bootstrap over seeds, {RESAMPLES:,} resamples]. Every mode runs on the same "
             f"learner (the `*-anneal` presets); the paper's numbers are from 100 x 100 grayscale frames.", "",
             "| mode (preset) | initial lane | survival | achievement | achievement per seed | paper (survival / achievement) |",
             "|---|---|---|---|---|---|"]
    for mode, body in results["modes"].items():
        runs = body["runs"]
        for lane in INITIAL_LANES:
            s, a = (across_seeds(runs, lane, f"{k}_rate") for k in ("survival", "achievement"))
            paper = PAPER_TABLE2.get(mode, {}).get(lane)
            lines.append(f"| {mode} ({body['method']}) | {lane} | {pct(s['rate'])} [{pct(s['ci95'][0])}, "
                         f"{pct(s['ci95'][1])}] | {pct(a['rate'])} [{pct(a['ci95'][0])}, {pct(a['ci95'][1])}] | "
                         + ", ".join(pct(x) for x in a["per_seed"])
                         + f" | {f'{paper[0]:g} / {paper[1]:g}' if paper else '-'} |")
    for name, lanes in results["baselines"].items():
        for lane in INITIAL_LANES:
            s, a = lanes[lane]["survival"]["rate"], lanes[lane]["achievement"]["rate"]
            paper = "50.7 / 50.3 (the paper's person, random lane)" if name == HUMAN_LIKE_ROW and lane == "random" else "-"
            lines.append(f"| {name} (driver) | {lane} | {pct(s)} | {pct(a)} | - | {paper} |")
    lines += ["", "**The answer**", ""] + answer(results)
    return "\n".join(lines) + "\n"


def run_paper(args: argparse.Namespace) -> dict:
    seed_list(args.seeds)
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    unknown = [m for m in modes if m not in MODES]
    if not modes or unknown:
        raise ConfigError(f"--modes: expected a comma-separated subset of {', '.join(MODES)}, got {args.modes!r}")
    out_dir = Path(args.out).resolve()
    args.out = str(out_dir)
    # Every mode's plan (configs, refusals) before anything is driven or trained.
    user = parse_set(args.set)
    base = load_run_config(args.config, {"env.scenario": args.scenario, "actor.workers": args.workers, **user})
    cfgs = [load_run_config(overrides={**method_settings(MODES[m]), **user}, base=base) for m in modes]
    uses_demos = {m: c.replay.demo_mode != "none" for m, c in zip(modes, cfgs)}
    shard = None
    if any(uses_demos.values()):
        episodes = demo_episodes_needed(cfgs, args.demo_episodes)
        out_dir.mkdir(parents=True, exist_ok=True)
        shard = ensure_shard(base.env, args.demonstrator, episodes, out_dir)
    else:
        episodes = 0
    for mode in modes:  # each refuses a bad setting now, before the first run
        protocol.plan(protocol_args(args, mode, shard if uses_demos[mode] else None))
    results: dict[str, Any] = {"kind": "paper", "scenario": args.scenario, "demonstrator": args.demonstrator,
                               "demo_episodes": episodes, "demo_shard": str(shard) if shard else None,
                               "env_steps": args.env_steps, "seeds": seed_list(args.seeds),
                               "eval_episodes": args.test_episodes, "eval_max_steps": args.eval_max_steps,
                               "command": command_line(), "modes": {}, "methods": {}, "baselines": {}}
    for mode in modes:
        write(f"paper: {mode} ({MODES[mode]})")
        r = protocol.run_protocol(protocol_args(args, mode, shard if uses_demos[mode] else None))
        body = r["methods"][MODES[mode]]
        results["modes"][mode] = {"method": MODES[mode], "test": r["test"], **body}
        results["methods"][mode] = body  # compare's layout: experiment replot and the curves read it
        results["baselines"] = r["baselines"]
    write_json(out_dir / "results.json", results)
    episodes_data, _ = collect_episodes(results, out_dir)  # each run's metrics.jsonl, at its run dir
    if episodes_data:
        write_episodes(episodes_data, out_dir)
        plot_curves(results, out_dir, episodes=episodes_data)
    table = render_table(results)
    (out_dir / "table.md").write_text(table)
    print(table)
    return results


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("paper", help="the paper's question: none, retention, rehearsal and dqfd on the same "
                                            "converging learner, with one demonstrator's shard (Table 2, figure 5)")
    p.add_argument("--scenario", default="straight", choices=protocol.SCENARIOS, help="the road")
    p.add_argument("--demonstrator", default="scripted", choices=DEMONSTRATORS,
                   help="who drives the demo shard: the scripted driver or the human-like stand-in (about 60 / 52 %% "
                        "on the straight road; not a person)")
    p.add_argument("--modes", default=",".join(MODES), help=f"comma-separated subset of {', '.join(MODES)}")
    p.add_argument("--seeds", default="0,1,2,3,4", help="comma-separated training seeds: one run per mode and seed")
    p.add_argument("--env-steps", type=positive_int, default=150_000, help="env-step budget of every run")
    p.add_argument("--demo-episodes", type=non_negative_int, default=0,
                   help=f"episodes in the demo shard (0: {DEMO_MARGIN:g}x what the largest demo region needs)")
    p.add_argument("--workers", type=positive_int, default=2, help="env workers (Ray actors) of each run")
    p.add_argument("--test-episodes", type=positive_int, default=200, help="test episodes per initial-lane setting")
    p.add_argument("--eval-max-steps", type=positive_int, default=300, help="test episode length (paper: 300)")
    p.add_argument("--validation-every", type=non_negative_int, default=None, metavar="ENV_STEPS",
                   help="env steps between greedy validation evaluations (default: --env-steps // 10)")
    p.add_argument("--validation-episodes", type=positive_int, default=20, help="episodes per validation evaluation")
    p.add_argument("--stability-target", type=fraction, default=0.93,
                   help="validation achievement after whose first crossing each protocol measures the largest drop")
    p.add_argument("--out", default="runs/paper", metavar="DIR", help="where each mode's protocol, the table and the "
                                                                      "figures go")
    p.add_argument("--config", help="base config file (YAML/TOML/JSON)")
    add_set_arg(p)
    p.set_defaults(func=lambda a: (run_paper(a), 0)[1])
