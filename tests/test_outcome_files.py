"""The studies' per-episode outcome files (``laneshift.tools.studies.outcome_files``): the ``laneshift eval
--episodes-out`` lines read back, and the compact CSV that a study commits holding the same outcomes.

Room: tests. May import: anything in laneshift, pytest.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from laneshift.tools.studies.outcome_files import (Outcome, achievement_by_start_lane, outcome_rows, read_outcomes,
                                                    write_outcomes_csv)


def _episodes_out(path: Path, first_seed: int, outcomes: list[tuple[bool, bool, int]]) -> None:
    lines = [json.dumps({"seed": first_seed + i, "start_lane": lane, "end_lane": 1, "steps": 300, "return": 1.0,
                         "survived": survived, "achieved": achieved, "crash": None})
             for i, (survived, achieved, lane) in enumerate(outcomes)]
    path.write_text("\n".join(lines) + "\n")


def test_the_csv_holds_what_the_episode_files_hold(tmp_path: Path) -> None:
    _episodes_out(tmp_path / "net-s0-non-target.jsonl", 200200, [(True, True, 0), (True, False, 2), (False, False, 0)])
    _episodes_out(tmp_path / "driver-random.jsonl", 200200, [(True, True, 1), (True, True, 2), (True, False, 0)])
    runs = read_outcomes(tmp_path)
    assert runs[("net-s0", "non-target")][200201] == Outcome(survived=True, achieved=False, start_lane=2)
    assert set(runs) == {("net-s0", "non-target"), ("driver", "random")}
    kept = tmp_path / "kept"
    kept.mkdir()
    write_outcomes_csv(runs, kept / "episodes.csv")
    assert read_outcomes(kept) == runs


def test_a_file_without_a_lane_in_its_name_is_refused(tmp_path: Path) -> None:
    _episodes_out(tmp_path / "net-s0.jsonl", 0, [(True, True, 0)])
    with pytest.raises(ValueError, match="initial lane"):
        read_outcomes(tmp_path)


def test_episode_seeds_with_a_gap_cannot_be_kept_as_strings(tmp_path: Path) -> None:
    runs = {("net", "random"): {0: Outcome(True, True, 0), 2: Outcome(True, True, 0)}}
    with pytest.raises(ValueError, match="consecutive"):
        write_outcomes_csv(runs, tmp_path / "episodes.csv")


def test_achievement_by_start_lane_pools_the_runs_and_counts_episodes_per_run(tmp_path: Path) -> None:
    _episodes_out(tmp_path / "a-s0-non-target.jsonl", 200200, [(True, True, 0), (True, False, 2), (False, False, 0)])
    _episodes_out(tmp_path / "a-s1-non-target.jsonl", 200200, [(True, True, 0), (True, True, 2), (True, True, 0)])
    runs = read_outcomes(tmp_path)
    assert achievement_by_start_lane(runs, ["a-s0"]) == {0: (0.5, 2), 2: (0.0, 1)}
    assert achievement_by_start_lane(runs, ["a-s0", "a-s1"]) == {0: (0.75, 2), 2: (0.5, 1)}


def test_outcome_rows_are_one_row_per_run_in_the_given_episode_order(tmp_path: Path) -> None:
    _episodes_out(tmp_path / "a-s0-random.jsonl", 200200, [(True, True, 0), (True, False, 2), (False, False, 0)])
    _episodes_out(tmp_path / "a-s1-random.jsonl", 200200, [(False, False, 0), (True, True, 2), (True, True, 0)])
    runs = read_outcomes(tmp_path)
    order = [200202, 200200]
    assert outcome_rows(runs, ["a-s0", "a-s1"], "random", order) == [[0.0, 1.0], [1.0, 0.0]]
    assert outcome_rows(runs, ["a-s0"], "random", order, "survived") == [[0.0, 1.0]]
