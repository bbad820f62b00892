"""``laneshift experiment curves``: the figure of published networks' validation curves, drawn from the
JSON beside each network alone; an agent not published, or published without a curve, is one line and
no figure.

Room: tests. May import: laneshift (any floor), pytest, the standard library and what the code under
test needs."""

from __future__ import annotations

import json

from laneshift.tools import cli
from laneshift.tools.studies.published_curves import published_curves


def _publish(directory, name: str, seed: int, achievement: list[float]) -> None:
    curve = [{"env_steps": 40_000 * (i + 1), "elapsed_s": 10.0 * i, "episodes": 20, "survival_rate": 1.0,
              "achievement_rate": a} for i, a in enumerate(achievement)]
    (directory / f"{name}-seed{seed}-final.json").write_text(json.dumps({"validation": {"curve": curve}}))


def test_each_agents_seeds_are_read_from_its_published_json_and_drawn(tmp_path, capsys):
    pub = tmp_path / "checkpoints"
    pub.mkdir()
    for seed, rates in enumerate(([0.8, 0.9, 0.95], [0.85, 0.9, 1.0])):
        _publish(pub, "merge-m", seed, rates)
    _publish(pub, "merge-m-seed1-x", 0, [0.1, 0.2])  # another name whose glob match would look like merge-m's
    _publish(pub, "straight-m", 4, [0.9, 0.95])
    assert set(published_curves(pub, "merge-m")) == {0, 1}
    assert published_curves(pub, "merge-m")[1][2]["achievement_rate"] == 1.0
    out = tmp_path / "fig" / "curves.png"
    argv = ["experiment", "curves", "merge=merge-m", "straight-m", "--published", str(pub), "--out", str(out)]
    assert cli.main(argv) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "2 agents" in capsys.readouterr().out


def test_an_agent_not_published_or_without_a_curve_is_one_line_and_no_figure(tmp_path, capsys):
    pub = tmp_path / "checkpoints"
    pub.mkdir()
    _publish(pub, "merge-m", 0, [0.8, 0.9])
    (pub / "curve-m-seed0-final.json").write_text(json.dumps({"test": {}}))
    _publish(pub, "short-m", 0, [0.8])
    out = tmp_path / "curves.png"
    for agents, needle in ((["merge-m", "roundabout-m"], "roundabout-m: no network published"),
                           (["curve-m"], "no validation curve in it"),
                           (["short-m"], "no two validation evaluations"),
                           (["a=merge-m", "a=merge-m"], "named twice")):
        assert cli.main(["experiment", "curves", *agents, "--published", str(pub), "--out", str(out)]) == 2
        assert needle in capsys.readouterr().err
    assert not out.exists()
