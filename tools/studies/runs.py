"""The training runs of a study and what they leave: each run's config (``method_config``), one
real local run with its console output kept in a log (``train_logged``), and its episodes read
back from ``metrics.jsonl`` (``run_episodes``, ``episode_curves``); a study's per-episode data kept
beside its results.json (``episodes.json``: ``collect_episodes``, ``write_episodes``) so its figures
can be redrawn once the run dirs are gone.

Room: the tools (studies). May import: anything in laneshift.
"""

from __future__ import annotations

import io
import json
import re
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from laneshift.config import RunConfig, load_run_config, method_settings
from laneshift.progress import progress


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
    (``steps 1,234/150,000 ...``) move ``bar`` (a line in another format just leaves it still).

    ``resume``: the first count above 0 is where the resumed run stood, not steps made now, so it
    becomes the bar's starting point (tqdm's ``initial``) and the rate and time left count only the
    steps this piece makes (it read 2,500 steps/s and seconds left for a pixel run at 35/s)."""

    _STEPS = re.compile(r"steps\s+([\d,]+)/([\d,]+)")
    # "| upd  1,234 (45/s) ... | v12 phase 1": the pre-training's updates, while no env step is made.
    _PRETRAINING = re.compile(r"\bupd\s+([\d,]+)\b.*\bphase 1\b")

    def __init__(self, bar, resume: bool = False, phase1_updates: int = 0):
        super().__init__()
        self.bar = bar
        self.resume = resume
        self.phase1_updates = phase1_updates

    def write(self, text: str) -> int:
        for line in text.splitlines():
            self._pretraining(line)
        for m in self._STEPS.finditer(text):
            done = min(int(m.group(1).replace(",", "")), int(self.bar.total or 0))
            if self.resume and self.bar.n == 0 and done > 0:
                self.resume = False
                self._start_at(done)
            elif done > self.bar.n:
                self.bar.update(done - self.bar.n)
        return super().write(text)

    def _pretraining(self, line: str) -> None:
        """The pre-training's update count on the bar (a pixel run pre-trains for 40 minutes before
        its first env step; the bar once stood at 0 all that time), redrawn at the bar's own pace
        (``update(0)``: tqdm redraws when its interval has passed)."""
        m = self._PRETRAINING.search(line)
        if m is not None:
            of = f"/{self.phase1_updates:,}" if self.phase1_updates else ""
            self.bar.set_postfix_str(f"pre-training {int(m.group(1).replace(',', '')):,}{of} updates", refresh=False)
        elif "phase 2" in line and self.bar.postfix:
            self.bar.set_postfix_str("", refresh=False)
        else:
            return
        self.bar.update(0)

    def _start_at(self, done: int) -> None:
        bar = self.bar
        if bar.disable:  # progress off: nothing to draw
            bar.n = done
            return
        bar.n = bar.initial = bar.last_print_n = done
        bar.start_t = bar.last_print_t = bar._time()
        bar.refresh()


def train_logged(cfg: RunConfig, log_path: Path, label: str | None = None, resume: bool = False) -> None:
    """One real local training run, its console output kept in ``log_path``; raises if it failed.
    ``label``: show the run's env steps as a progress bar on stderr with this label. ``resume``:
    continue the unfinished run in ``cfg``'s run dir (``laneshift train --resume``), its output
    appended to the log."""
    from laneshift.deploy.local import train_local

    with progress(total=cfg.train.env_steps, desc=label or "", unit="step", leave=False,
                  disable=label is None) as bar:
        log = _TrainLog(bar, resume=resume, phase1_updates=cfg.learner.phase1_updates)
        rc = train_local(cfg, out=log, resume=resume)
    with open(log_path, "a" if resume else "w") as f:
        f.write(log.getvalue())
    if rc != 0:
        raise RuntimeError(f"training run {cfg.train.run_dir} failed (rc {rc}); see {log_path}")


def episode_curves(run_dir: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
