"""The rates a resumed run shows while it trains: the launcher's status line (``laneshift train``)
and a study's per-run progress bar (``experiment protocol``/``compare``) count the steps made in
this launch, not those a resumed run had made before it (they once read 2,500 steps/s and seconds
left for a pixel run making 35 steps/s).

Room: tests, unit. May import: laneshift.deploy.progress_line, laneshift.tools.studies.runs,
laneshift.progress, pytest and the standard library.
"""

from __future__ import annotations

import io

from laneshift.deploy.progress_line import Progress
from laneshift.progress import progress
from laneshift.tools.studies.runs import _TrainLog


def _status_line(steps: int, budget: int = 150_000) -> str:
    return f"[  10.0s] steps {steps:>7,}/{budget:,} (   35/s) | ep 10 return 1.00\n"


def test_the_status_line_shows_the_learners_own_rate():
    out = io.StringIO()
    line = Progress(out, budget=150_000)
    line.last = {"env_steps": 133_536, "env_steps_per_s": 34.6, "updates": 9_000}
    assert "steps 133,536/150,000 (   35/s)" in line.line()
    line.last = {"env_steps": 100}  # a status without the rate (an older learner): "-", as for updates
    assert "steps     100/150,000" in line.line()


def test_a_resumed_runs_bar_starts_where_the_run_stood(monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")
    with progress(total=150_000, desc="train", unit="step", file=io.StringIO()) as bar:
        log = _TrainLog(bar, resume=True)
        log.write(_status_line(0))  # the launcher's lines before the learner reports the run's count
        log.write(_status_line(133_536))
        assert bar.n == bar.initial == 133_536  # where the run stood: not steps made now
        log.write(_status_line(134_000))
        assert bar.n == 134_000 and bar.format_dict["initial"] == 133_536
        assert "133,536" in log.getvalue()  # the log keeps every line as written


def test_a_new_runs_bar_counts_from_zero(monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")
    with progress(total=150_000, desc="train", unit="step", file=io.StringIO()) as bar:
        log = _TrainLog(bar)
        log.write(_status_line(2_000))
        log.write(_status_line(1_500))  # a count that goes back leaves the bar still
        assert bar.n == 2_000 and bar.initial == 0


def _phase1_line(updates: int) -> str:
    return (f"[  10.0s] steps       0/150,000 (    0/s) | ep     0 return - | upd {updates:>6,} (50/s) loss 1.0"
            " | v3 phase 1\n")


def test_the_bar_shows_the_pre_trainings_updates_before_the_first_env_step(monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")
    out = io.StringIO()
    with progress(total=150_000, desc="train", unit="step", file=out) as bar:
        log = _TrainLog(bar, phase1_updates=120_000)
        log.write(_phase1_line(500))
        log.write(_phase1_line(1_500))
        log.write(_status_line(64).replace("(   35/s) |", "(   35/s) | upd 120,100 (40/s) | v9 phase 2"))
        assert bar.n == 64 and not bar.postfix
    lines = out.getvalue().splitlines()
    assert any(line.endswith("pre-training 500/120,000 updates") for line in lines), lines
    assert any(line.endswith("pre-training 1,500/120,000 updates") for line in lines), lines
    assert lines[-1].startswith("train: 64/150000 step") and "pre-training" not in lines[-1], lines


def test_with_progress_off_the_lines_only_go_to_the_log(monkeypatch):
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    with progress(total=150_000, desc="train", unit="step") as bar:
        log = _TrainLog(bar, resume=True, phase1_updates=120_000)
        for text in (_phase1_line(500), _status_line(133_536), _status_line(134_000)):
            log.write(text)
    assert log.getvalue().count("\n") == 3
