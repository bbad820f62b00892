"""The whole fault suite, as ``laneshift chaos`` runs it: every process, launcher, storage and
control-plane fault against a real 2-worker run; each row must survive with every transition
stored or counted. Long (about 8 minutes here), so behind the ``chaos`` marker:

    .venv/bin/python -m pytest -m chaos tests/test_chaos_suite.py

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.chaos


def test_every_fault_of_the_suite_survives_with_every_loss_counted(tmp_path):
    faults = ["worker", "learner", "router", "replay", "replay-after-checkpoint", "stats-flood",
              "launcher-sigterm", "launcher-kill"]
    if os.geteuid() == 0:  # a tmpfs and a read-only bind mount need root
        faults += ["disk-full", "unwritable"]
    out = tmp_path / "chaos.json"
    done = subprocess.run([sys.executable, "-m", "laneshift", "chaos", "--faults", ",".join(faults), "--demos",
                           "--work-dir", str(tmp_path / "work"), "--out", str(out)],
                          capture_output=True, text=True, timeout=1800)
    rows = json.loads(out.read_text())["rows"]
    assert [r["fault"] for r in rows] == faults
    for row in rows:
        assert row["survived"], (row, done.stderr[-3000:])
        assert row["unaccounted"] == 0 and row["left_behind"] == 0, row
        assert row["versions_monotonic"], row
        assert row["demo_identical"] in (True, None), row
    assert done.returncode == 0, done.stderr[-3000:]
