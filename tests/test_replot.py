"""`laneshift experiment replot`: a compare study's table and figures redrawn from its kept data,
on a tiny synthetic results dir (no training): the across-seed table, the Table 2 bar chart, the
curves against env steps, episodes and wall clock and the periodic greedy evaluations from the runs' metrics.jsonl, then again from the
episodes.json it keeps once the run dirs are gone; older logs without env steps; bad paths.
Room: tests, unit. May import: laneshift.tools.studies, laneshift.tools.cli, numpy, pytest and the standard library.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from laneshift.tools import cli
from laneshift.tools.studies.runs import EPISODES_FILE
from laneshift.tools.studies.table2 import render_table, table2_rows

PNG = b"\x89PNG"


def _eval(survival: float, achievement: float, episodes: int = 100) -> dict:
    return {"episodes": episodes, "survival_rate": survival, "achievement_rate": achievement}


def _metrics(run_dir: Path, seed: int, episodes: int = 60, env_steps: bool = True) -> None:
    """A run's metrics.jsonl: learner records and ``episodes`` episode records of 50-150 steps."""
    rng = np.random.default_rng(seed)
    run_dir.mkdir(parents=True)
    t, steps, lines = 1000.0 + seed, 0, []
    lines.append({"kind": "learner", "step": 0, "time": t, "env_steps": 0, "updates": 0})
    for i in range(episodes):
        length = int(rng.integers(50, 150))
        steps += length
        t += length / 100
        rec = {"kind": "episode", "step": steps, "time": t, "return": float(i + rng.normal()), "length": length,
               "episode": i + 1}
        if env_steps:
            rec["env_steps"] = steps
        lines.append(rec)
        if env_steps and i % 20 == 19:  # a periodic greedy evaluation (train.eval_every)
            lines.append({"kind": "eval", "step": steps, "time": t, "env_steps": steps, "episodes": 10,
                          "survival_rate": 0.1 * (i // 20), "achievement_rate": 0.05 * (i // 20),
                          "return_mean": float(i), "length_mean": 90.0, "eval_s": 1.0})
    (run_dir / "metrics.jsonl").write_text("\n".join(json.dumps(r) for r in lines) + "\n")


def _study(tmp_path: Path, env_steps: bool = True) -> Path:
    """results.json of a 2-method x 2-seed compare study (plus one baseline) and its run dirs."""
    out = tmp_path / "study"
    out.mkdir()
    methods = {}
    for method, rates in (("none", [(0.4, 0.4), (0.05, 0.05)]), ("rehearsal", [(0.6, 0.5), (0.6, 0.5)])):
        runs = []
        for seed, (s, a) in enumerate(rates):
            run_dir = tmp_path / "runs" / f"{method}-s{seed}"
            _metrics(run_dir, seed, env_steps=env_steps)
            runs.append({"seed": seed, "run_dir": str(run_dir), "wall_s": 1.0,
                         "eval": {"random": _eval(s, a), "non-target": _eval(s / 2, a / 2)}})
        methods[method] = {"runs": runs}  # an older file's shape: no per-lane numbers stored
    lane = {"survival": {"rate": 0.46, "ci95": [0.39, 0.53], "episodes": 200},
            "achievement": {"rate": 0.16, "ci95": [0.12, 0.22], "episodes": 200}}
    results = {"scenario": "straight", "env_steps": 9000, "seeds": [0, 1], "eval_episodes": 100,
               "eval_max_steps": 300, "methods": methods, "baselines": {"keep-lane": {"random": lane, "non-target": lane}}}
    (out / "results.json").write_text(json.dumps(results))
    return out


def test_table_rows_carry_the_across_seed_interval_and_the_pooled_one(tmp_path):
    results = json.loads((_study(tmp_path) / "results.json").read_text())
    rows = {(name, lane): rest for name, lane, *rest in table2_rows(results)}
    seeds, survival, achievement, pooled_s, _ = rows[("none", "random")]
    assert seeds == 2 and survival["per_seed"] == [0.4, 0.05]
    assert survival["rate"] == pytest.approx(0.225)
    assert survival["ci95"] == [pytest.approx(0.05), pytest.approx(0.4)]  # two seeds: their range
    # Pooled over the 200 episodes: the same rate, a Wilson interval much narrower than the seeds' spread.
    assert pooled_s["rate"] == pytest.approx(0.225) and pooled_s["episodes"] == 200
    assert pooled_s["ci95"][1] - pooled_s["ci95"][0] < 0.35 / 2
    _, survival, _, _, _ = rows[("rehearsal", "random")]
    assert survival["ci95"] == [pytest.approx(0.6), pytest.approx(0.6)]  # seeds agree: zero width
    _, survival, _, pooled_s, _ = rows[("keep-lane (baseline)", "random")]
    assert survival == {"rate": 0.46, "ci95": None} and pooled_s["ci95"] == [0.39, 0.53]
    table = render_table(results)
    assert "| none | random | 2 | 22% [5%, 40%] | 22% [5%, 40%] | 22% [17%, 29%] | 22% [17%, 29%] |" in table
    assert "| keep-lane (baseline) | random | - | 46% | 16% | 46% [39%, 53%] | 16% [12%, 22%] |" in table
    assert "survival (pooled)" in table and "bootstrap over seeds" in table


def test_replot_draws_the_figures_from_the_runs_then_from_the_kept_episodes(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    study = _study(tmp_path)
    assert cli.main(["experiment", "replot", "--results", str(study), "--window", "10"]) == 0
    for name in ("table2.png", "curves_env_steps.png", "curves_episodes.png", "curves_wallclock.png",
                 "curves_eval.png"):
        assert (study / name).read_bytes()[:4] == PNG, name
    assert "| rehearsal | non-target | 2 |" in (study / "table.md").read_text()
    kept = json.loads((study / EPISODES_FILE).read_text())["runs"]
    assert set(kept) == {"none-s0", "none-s1", "rehearsal-s0", "rehearsal-s1"}
    first = kept["none-s0"]
    assert len(first["return"]) == len(first["env_steps"]) == len(first["time_s"]) == 60
    assert first["env_steps"] == sorted(first["env_steps"]) and first["time_s"][0] > 0  # since the run's start
    assert [e["survival_rate"] for e in first["evals"]] == pytest.approx([0.0, 0.1, 0.2])
    assert [e["env_steps"] for e in first["evals"]] == [first["env_steps"][i] for i in (19, 39, 59)]
    assert "wrote" in capsys.readouterr().out
    # The run dirs gone (as in docs/results): the curves come from episodes.json, which stays as it was.
    for run_dir in (tmp_path / "runs").iterdir():
        (run_dir / "metrics.jsonl").unlink()
    before = (study / EPISODES_FILE).read_text()
    (study / "curves_env_steps.png").unlink()
    out = tmp_path / "elsewhere"
    assert cli.main(["experiment", "replot", "--results", str(study), "--out", str(out)]) == 0
    assert (out / "curves_env_steps.png").read_bytes()[:4] == PNG and (out / "table2.png").exists()
    assert (out / "curves_eval.png").read_bytes()[:4] == PNG  # the evaluations kept in episodes.json
    assert (study / EPISODES_FILE).read_text() == before and not (out / EPISODES_FILE).exists()


def test_replot_without_env_steps_draws_against_episodes(tmp_path, monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    study = _study(tmp_path, env_steps=False)
    assert cli.main(["experiment", "replot", "--results", str(study), "--window", "10"]) == 0
    assert (study / "curves_episodes.png").read_bytes()[:4] == PNG
    assert (study / "curves_wallclock.png").exists() and not (study / "curves_env_steps.png").exists()
    assert not (study / "curves_eval.png").exists()  # these runs had no periodic evaluation


def test_replot_without_episode_data_leaves_the_curves_alone(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    study = _study(tmp_path)
    for run_dir in (tmp_path / "runs").iterdir():
        (run_dir / "metrics.jsonl").unlink()
    (study / "curves_episodes.png").write_bytes(b"old figure")
    assert cli.main(["experiment", "replot", "--results", str(study)]) == 0
    assert (study / "curves_episodes.png").read_bytes() == b"old figure"
    assert (study / "table2.png").read_bytes()[:4] == PNG and not (study / "curves_env_steps.png").exists()
    assert "no per-episode data" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["missing", "not-json", "other-study"])
def test_a_bad_results_dir_is_one_line_and_exit_2(tmp_path, capsys, case):
    target = tmp_path / "r"
    if case != "missing":
        target.mkdir()
        (target / "results.json").write_text("{oops" if case == "not-json" else json.dumps({"runs": {}}))
    assert cli.main(["experiment", "replot", "--results", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("laneshift experiment replot: --results ")
    assert "Traceback" not in err


def _more_seeds(tmp_path: Path, seed: int = 2, **change) -> Path:
    """Another study of the same setting with one more seed of both methods (its own run dirs)."""
    out = tmp_path / f"more-{seed}"
    out.mkdir()
    methods = {}
    for method in ("none", "rehearsal"):
        run_dir = tmp_path / f"more-runs-{seed}" / f"{method}-s{seed}"
        _metrics(run_dir, seed)
        methods[method] = {"runs": [{"seed": seed, "run_dir": str(run_dir), "wall_s": 1.0,
                                     "eval": {"random": _eval(0.3, 0.3), "non-target": _eval(0.1, 0.1)}}]}
    results = {"scenario": "straight", "env_steps": 9000, "seeds": [seed], "eval_episodes": 100,
               "eval_max_steps": 300, "methods": methods, "baselines": {}, **change}
    (out / "results.json").write_text(json.dumps(results))
    return out


def test_replot_add_merges_the_seeds_of_another_study(tmp_path, monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    study, more = _study(tmp_path), _more_seeds(tmp_path)
    out = tmp_path / "merged"
    assert cli.main(["experiment", "replot", "--results", str(study), "--add", str(more), "--out", str(out),
                     "--window", "10"]) == 0
    merged = json.loads((out / "results.json").read_text())
    assert merged["seeds"] == [0, 1, 2]
    none = merged["methods"]["none"]
    assert [r["seed"] for r in none["runs"]] == [0, 1, 2]
    assert none["random"]["survival"]["per_seed"] == [0.4, 0.05, 0.3]
    assert none["random"]["survival"]["rate"] == pytest.approx((0.4 + 0.05 + 0.3) / 3)
    assert "keep-lane" in merged["baselines"]  # the first study's baselines stay
    assert "| none | random | 3 |" in (out / "table.md").read_text()
    kept = json.loads((out / EPISODES_FILE).read_text())["runs"]
    assert set(kept) == {f"{m}-s{s}" for m in ("none", "rehearsal") for s in (0, 1, 2)}
    assert (out / "curves_episodes.png").read_bytes()[:4] == PNG
    assert json.loads((study / "results.json").read_text())["seeds"] == [0, 1]  # the inputs are left as they were


@pytest.mark.parametrize("case", ["other-budget", "same-seed"])
def test_replot_add_refuses_what_is_not_the_same_study(tmp_path, capsys, case):
    study = _study(tmp_path)
    more = _more_seeds(tmp_path, env_steps=5000) if case == "other-budget" else _more_seeds(tmp_path, seed=1)
    assert cli.main(["experiment", "replot", "--results", str(study), "--add", str(more),
                     "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ("env_steps 9000 vs 5000" in err if case == "other-budget" else "seed(s) [1]" in err)
