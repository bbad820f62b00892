"""What `laneshift` shows a user: --help (every option of every command says what it is, with its
default), --version, and progress lines on stderr when stderr is not a terminal.

Walks the real parser (``laneshift.tools.cli.build_parser``), in process; two subprocesses check the
installed version and a long command's stdout/stderr split. Room: tests, unit. May import: the laneshift CLI and
``laneshift.progress``, pytest and the standard library.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
from importlib.metadata import version

import pytest

from laneshift.tools.cli import build_parser, leaf_parsers


def _commands(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """Every parser in the tree: the top level, each command group and each leaf command."""
    out = [parser]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                out += _commands(child)
    return out


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions
            if a.option_strings and not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))]


#: Options of commands whose module is not the CLI's own (tools/chaos/): known, to be given a help there.
KNOWN_WITHOUT_HELP: set[str] = set()


def test_every_option_of_every_command_has_a_help_text():
    parser = build_parser()
    commands = _commands(parser)
    assert {p.prog for p in leaf_parsers(parser)} >= {
        "laneshift train", "laneshift eval", "laneshift replay inspect", "laneshift demos generate",
        "laneshift experiment compare", "laneshift experiment checkpoints", "laneshift experiment sb3",
        "laneshift experiment presets", "laneshift bench env", "laneshift bench replay"}
    missing = [f"{p.prog} {'/'.join(a.option_strings)}" for p in commands for a in _options(p)
               if not (a.help or "").strip()]
    missing = [m for m in missing if m not in KNOWN_WITHOUT_HELP]
    assert not missing, "options without help=: " + ", ".join(missing)


def test_every_command_has_a_help_line_in_its_group():
    """Every command but an old name kept for a renamed one (its parser's default ``renamed_to`` says
    the new name), which is left out of the list."""
    for parser in _commands(build_parser()):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                helps = {c.dest: (c.help or "").strip() for c in action._choices_actions}
                old = {name for name, p in action.choices.items() if p.get_default("renamed_to")}
                assert set(helps) == set(action.choices) - old and all(helps.values()), (parser.prog, helps)


def test_help_shows_defaults_and_renders_for_every_command(capsys):
    for command in _commands(build_parser()):
        text = command.format_help()  # every help string formats (no stray %)
        assert text.startswith("usage: ")
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["eval", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "greedy evaluation episodes (default: 100)" in text
    assert "--seed SEED" in text and "(default: 0)" in text
    assert "(default: None)" not in text  # options without a default say nothing about it


def test_a_core_command_builds_its_parser_without_the_tools():
    """`laneshift train`'s process is the run's launcher: it never imports the tools' modules
    (gymnasium, matplotlib, the demo and study code); a tool command gets its own, and a word
    that names no command gets the full list."""
    code = ("import sys; from laneshift.tools.cli import build_parser; build_parser(['train', '--local']); "
            "print(sorted(m for m in ('gymnasium', 'matplotlib', 'numpy', 'laneshift.demos', 'laneshift.tools.bench', "
            "'laneshift.tools.studies') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"

    def commands(argv):
        action = next(a for a in build_parser(argv)._actions if isinstance(a, argparse._SubParsersAction))
        return set(action.choices)

    everything = commands(None)
    assert {"train", "demos", "experiment", "bench", "chaos"} <= everything
    assert commands(["--help"]) == commands(["trian"]) == everything
    assert commands(["train", "--local"]) == everything - {"demos", "experiment", "bench", "chaos"}
    assert commands(["bench", "run"]) == commands(["train"]) | {"bench"}


def test_version_flag_prints_the_installed_version():
    proc = subprocess.run([sys.executable, "-m", "laneshift.tools.cli", "--version"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"laneshift {version('laneshift')}"


def test_progress_off_a_terminal_is_plain_lines_without_carriage_returns(monkeypatch):
    from laneshift.progress import progress

    monkeypatch.setenv("LANESHIFT_PROGRESS_S", "0")
    out = io.StringIO()
    for _ in progress(range(3), desc="eval", unit="episode", file=out):
        pass
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue() and "\x1b" not in out.getvalue()
    assert lines[-1].startswith("eval: 3/3 episode (100 %)") and len(lines) == len(set(lines)) <= 4, lines
    monkeypatch.setenv("LANESHIFT_PROGRESS", "0")
    quiet = io.StringIO()
    assert list(progress(range(3), desc="eval", file=quiet)) == [0, 1, 2] and quiet.getvalue() == ""


def test_demos_generate_reports_progress_on_stderr_and_its_result_on_stdout(tmp_path):
    env = {**os.environ, "LANESHIFT_PROGRESS_S": "0"}
    proc = subprocess.run([sys.executable, "-m", "laneshift.tools.cli", "demos", "generate", "--scenario", "lka",
                           "--episodes", "3", "--max-steps", "20", "--out", str(tmp_path / "d")],
                          capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("wrote ") and len(proc.stdout.splitlines()) == 1  # no progress on stdout
    assert "demos generate: 3/3 episode (100 %)" in proc.stderr, proc.stderr


def test_help_is_for_users_and_train_says_what_its_shortcuts_leave_in_place(monkeypatch):
    top = build_parser().format_help()
    assert "Room:" not in top and "May import" not in top  # the module's note for developers stays out
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    train = next(p for p in _commands(build_parser(["train"])) if p.prog.endswith(" train"))
    text = " ".join(train.format_help().split())
    assert "(default: actor.workers = 2)" in text and "(default: train.env_steps = 20000)" in text
    assert "everything on this machine (the default;" in text
    monkeypatch.setenv("RAY_ADDRESS", "10.1.2.3:6379")
    train = next(p for p in _commands(build_parser(["train"])) if p.prog.endswith(" train"))
    text = " ".join(train.format_help().split())
    assert "RAY_ADDRESS=10.1.2.3:6379 is set, so without --local the run goes to that cluster" in text
