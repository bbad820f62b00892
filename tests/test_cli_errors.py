"""Bad input to any `laneshift` command: a non-zero exit and one short line on stderr, no traceback.

Each case runs the real command line (``python -m laneshift.tools.cli``) as a subprocess, with input
that every command must refuse before doing any work: an unknown scenario, a malformed --set,
missing files or run dirs, bad numbers, an unreachable zenoh router. A case takes the CLI's
start-up time (a few seconds), nothing more; they run a few at a time. Room: tests, system (the laneshift command in subprocesses). May import: the standard library and pytest.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

#: (id, argv with {tmp} for the test's directory, expected exit code, text the error line must hold)
CASES = [
    ("no-command", [], 2, "COMMAND"),
    ("unknown-command", ["trian"], 2, "invalid choice"),
    ("train-unknown-scenario", ["train", "--scenario", "highway", "--run-dir", "{tmp}/t"], 2, "highway"),
    ("train-bad-env-steps", ["train", "--env-steps", "lots", "--run-dir", "{tmp}/t"], 2, "env_steps"),
    ("train-resume-no-run", ["train", "--resume", "{tmp}/nope"], 2, "no run there"),
    ("replay-server-missing-config", ["replay-server", "--config", "{tmp}/missing.yaml"], 2, "missing.yaml"),
    ("learner-malformed-set", ["learner", "--set", "nodot"], 2, "SECTION.FIELD=VALUE"),
    ("router-bad-endpoint", ["router", "--listen", "garbage"], 2, "garbage"),
    ("eval-missing-checkpoint", ["eval", "--checkpoint", "{tmp}/none.safetensors"], 2, "none.safetensors"),
    ("eval-negative-episodes", ["eval", "--checkpoint", "{tmp}/x", "--episodes", "-3"], 2, "--episodes"),
    ("eval-unknown-scenario", ["eval", "--checkpoint", "{tmp}/x", "--scenario", "highway"], 2, "highway"),
    ("eval-checkpoint-and-driver", ["eval", "--checkpoint", "{tmp}/x", "--driver", "scripted"], 2, "not allowed"),
    ("eval-driver-on-lka", ["eval", "--driver", "scripted", "--scenario", "lka"], 2, "lane-change roads only"),
    ("eval-episodes-out-no-folder", ["eval", "--driver", "scripted", "--episodes-out", "{tmp}/no/x.jsonl"], 2,
     "not a file in an existing folder"),
    ("replay-inspect-bad-router", ["replay", "inspect", "--router", "garbage"], 2, "garbage"),
    ("replay-inspect-bad-interval", ["replay", "inspect", "--interval", "-1"], 2, "--interval"),
    ("demos-generate-unknown-scenario",
     ["demos", "generate", "--scenario", "highway", "--episodes", "1", "--out", "{tmp}/d"], 2, "highway"),
    ("demos-generate-unknown-env-kwarg",
     ["demos", "generate", "--scenario", "straight", "--episodes", "1", "--out", "{tmp}/d", "--env-kwarg", "bogus=1"],
     2, "bogus"),
    ("demos-record-unknown-scenario",
     ["demos", "record", "--scenario", "highway", "--episodes", "1", "--out", "{tmp}/r"], 2, "highway"),
    ("demos-inspect-missing-shard", ["demos", "inspect", "{tmp}/nope"], 2, "nope"),
    ("compare-malformed-set", ["experiment", "compare", "--set", "nodot", "--out", "{tmp}/c"], 2, "nodot"),
    ("compare-unknown-method", ["experiment", "compare", "--methods", "none,bogus", "--out", "{tmp}/c"], 2, "bogus"),
    ("compare-bad-seeds", ["experiment", "compare", "--seeds", "0,x", "--out", "{tmp}/c"], 2, "--seeds"),
    ("checkpoints-no-run-dir", ["experiment", "checkpoints", "--run-dir", "{tmp}/nope"], 2, "no run there"),
    ("checkpoints-bad-lane", ["experiment", "checkpoints", "--run-dir", "{tmp}", "--initial-lanes", "left"], 2,
     "--initial-lanes"),
    ("sb3-unknown-scenario", ["experiment", "sb3", "--scenario", "highway", "--out", "{tmp}/s"], 2, "highway"),
    ("sb3-zero-eval-every", ["experiment", "sb3", "--eval-every", "0", "--out", "{tmp}/s"], 2, "--eval-every"),
    ("presets-unknown-condition", ["experiment", "presets", "--presets", "9", "--out", "{tmp}/p"], 2, "9"),
    ("bench-env-zero-steps", ["bench", "env", "--steps", "0"], 2, "--steps"),
    ("bench-replay-zero-duration", ["bench", "replay", "--duration", "0"], 2, "--duration"),
    ("bench-learner-one-round", ["bench", "learner", "--rounds", "1"], 2, "--rounds"),
    ("chaos-unknown-fault", ["chaos", "--faults", "nope", "--work-dir", "{tmp}/chaos"], 2, "nope"),
]


def _run(argv: list[str], cwd: Path, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}  # train must not find a cluster
    return subprocess.run([sys.executable, "-m", "laneshift.tools.cli", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def _one_line_error(proc: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in proc.stdout + proc.stderr, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert len(lines[0]) < 400, lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def refused(tmp_path_factory) -> dict[str, tuple[subprocess.CompletedProcess, Path]]:
    """Every case's finished command, run a few at a time (each is mostly the CLI's start-up)."""

    def one(case: tuple) -> tuple[subprocess.CompletedProcess, Path]:
        name, argv = case[0], case[1]
        tmp = tmp_path_factory.mktemp(name)
        return _run([a.replace("{tmp}", str(tmp)) for a in argv], cwd=tmp), tmp

    with ThreadPoolExecutor(max_workers=max(2, min(4, os.cpu_count() or 2))) as pool:
        return dict(zip([c[0] for c in CASES], pool.map(one, CASES)))


@pytest.mark.parametrize("name, code, says", [(c[0], c[2], c[3]) for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_a_usage_exit_code(refused, name, code, says):
    proc, tmp = refused[name]
    line = _one_line_error(proc)
    assert proc.returncode == code, (proc.returncode, line)
    assert says in line, line
    assert line.startswith("laneshift"), line  # says which command refused
    assert not (tmp / "c").exists() and not (tmp / "p").exists()  # refused before creating anything


def test_replay_inspect_gives_up_on_a_router_that_does_not_answer(tmp_path):
    started = time.monotonic()
    proc = _run(["replay", "inspect", "--router", "tcp/127.0.0.1:1", "--run-id", "run", "--connect-timeout", "1"],
                cwd=tmp_path, timeout=30)
    elapsed = time.monotonic() - started
    line = _one_line_error(proc)
    assert proc.returncode != 0
    assert line == "laneshift replay inspect: no zenoh router answered at tcp/127.0.0.1:1 within 1 s"
    assert elapsed < 10, elapsed  # start-up plus the 1 s timeout, not zenoh's forever
