"""The current performance table: rendered from one `bench all` JSON, and docs/performance.md holds
exactly that rendering (so the page's figures come from one measured source with its revision).

Room: tests, unit. May import: laneshift.tools.bench.report, pytest, the standard library."""

from __future__ import annotations

import json
from pathlib import Path

from laneshift.tools import cli
from laneshift.tools.bench.report import BEGIN, END, render, rows, splice

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "bench-all.json"


def test_performance_md_holds_the_table_rendered_from_the_committed_bench_all_json():
    page = (ROOT / "docs" / "performance.md").read_text()
    block = render(json.loads(RESULTS.read_text()))
    assert page[page.index(BEGIN):page.index(END) + len(END)] + "\n" == block, \
        "docs/performance.md is stale: laneshift bench report --update docs/performance.md"


def test_every_row_names_its_figure_and_command_and_missing_benchmarks_leave_no_row():
    results = json.loads(RESULTS.read_text())
    table = rows(results)
    assert len(table) >= 12 and all(command.startswith("`") for _, _, command in table)
    assert any(what.startswith("against RLlib") and figure == f"{results['targets']['vs_rllib_env_steps']:.1f}x, "
               f"{results['targets']['vs_rllib_rss']:.2f}x RSS" for what, figure, _ in table)
    partial = {"revision": "abc1234", "time": "2026-01-01T00:00:00", "env": results["env"]}
    assert [what for what, _, _ in rows(partial)] == [
        "env steps/s, one lane-change env (vector observation)",
        "env steps/s against highway-env's highway-fast-v0 (same machine)",
        "env steps/s, grayscale 4 x 100 x 100 observation"]
    assert "revision `abc1234`" in render(partial)


def test_update_replaces_only_the_marked_block(tmp_path, capsys):
    page = tmp_path / "perf.md"
    page.write_text(f"# Title\n\nbefore\n\n{BEGIN}\nold table\n{END}\n\nafter\n")
    assert cli.main(["bench", "report", "--results", str(RESULTS), "--update", str(page)]) == 0
    text = page.read_text()
    assert text.startswith("# Title\n\nbefore\n\n" + BEGIN) and text.endswith(END + "\n\nafter\n")
    assert "old table" not in text and "| what | measured | command |" in text
    assert splice(text, render(json.loads(RESULTS.read_text()))) == text
