"""A run without Ray: ``laneshift replay-server`` (the zenoh router too), ``laneshift learner`` and
``laneshift worker`` started by hand, one process each, as a user would on a machine without Ray
(docs/results/pixels-gpu/run_gpu.py does so on a GPU machine).

Room: tests, system (real laneshift processes; the `system` marker). May import: laneshift (any
floor), pytest, the standard library and what the code under test needs.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

from laneshift import transport, wire
from laneshift.config import load_run_config, save_run_config
from laneshift.deploy.processes import ProcessGroup, terminate, wait_for_file

FAST = {"env.scenario": "lka", "actor.workers": 2, "actor.send_every": 50, "learner.hidden": "32,32",
        "learner.batch_size": 32, "learner.publish_every": 5, "replay.min_size": 100,
        "replay.samples_per_insert": 4, "replay.spi_tolerance": 512}


def _summary(log: str) -> dict:
    return json.loads([line for line in log.splitlines() if line.startswith("{")][-1])


def test_a_run_of_separate_processes_spends_the_budget_and_stops_on_signals(tmp_path):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    cfg = load_run_config(overrides={**FAST, "transport.router": endpoint, "train.env_steps": 2000,
                                     "train.run_dir": str(tmp_path)})
    config = str(save_run_config(cfg, tmp_path / "config.yaml"))
    py = [sys.executable, "-m", "laneshift"]
    group = ProcessGroup(tmp_path / "logs")
    try:
        group.start("replay-server", [*py, "replay-server", "--config", config, "--embedded-router",
                                      "--ready-file", str(tmp_path / "ready")])
        wait_for_file(tmp_path / "ready", 60, group, "replay-server")
        group.start("learner", [*py, "learner", "--config", config])
        for i in range(2):
            group.start(f"w{i}", [*py, "worker", "--config", config, "--index", str(i)])
        for i in range(2):  # each worker spends its share and exits with its summary
            assert group.procs[f"w{i}"].wait(120) == 0, group.log_tail(f"w{i}")
            summary = _summary((tmp_path / "logs" / f"w{i}.log").read_text())
            assert summary["name"] == f"w{i}" and summary["env_steps"] == 1000 and summary["resumed_at"] == 0
        with transport.open_session(cfg.transport) as session:
            reply = transport.query(session, wire.replay_stats_key(cfg.transport.run_id), b"", 5.0)
        assert wire.decode_json(reply)["tables"]["online"]["inserted"] == 2000
        # A worker started again resumes where the replay server says it stands: nothing to do.
        group.start("w0-again", [*py, "worker", "--config", config, "--index", "0"])
        assert group.procs["w0-again"].wait(60) == 0
        again = _summary((tmp_path / "logs" / "w0-again.log").read_text())
        assert again["resumed_at"] == 1000 and again["env_steps"] == 1000
        # SIGTERM: the learner writes its final network, the replay server its final checkpoint.
        assert terminate(group.procs["learner"], grace_s=30) == 0
        assert (tmp_path / "checkpoints" / "final.safetensors").exists()
        assert terminate(group.procs["replay-server"], grace_s=30) == 0
        assert json.loads((tmp_path / "replay_checkpoint" / "meta.json").read_text())["items"] == 2000
    finally:
        group.stop_all()


def test_a_worker_stops_on_sigterm_with_its_summary_and_a_bad_index_is_one_line(tmp_path):
    endpoint = f"tcp/127.0.0.1:{transport.free_tcp_port()}"
    cfg = load_run_config(overrides={**FAST, "transport.router": endpoint, "train.env_steps": 10_000_000,
                                     "replay.samples_per_insert": 0, "train.run_dir": str(tmp_path)})
    config = str(save_run_config(cfg, tmp_path / "config.yaml"))
    py = [sys.executable, "-m", "laneshift"]
    bad = subprocess.run([*py, "worker", "--config", config, "--index", "2"], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines() == [
        "worker: --index 2: actor.workers is 2 (indexes 0..1)"]
    group = ProcessGroup(tmp_path / "logs")
    try:
        group.start("replay-server", [*py, "replay-server", "--config", config, "--embedded-router",
                                      "--ready-file", str(tmp_path / "ready")])
        wait_for_file(tmp_path / "ready", 60, group, "replay-server")
        group.start("learner", [*py, "learner", "--config", config])  # a worker acts once it has weights
        group.start("w1", [*py, "worker", "--config", config, "--index", "1"])
        deadline = time.monotonic() + 60  # until it has stored something
        with transport.open_session(cfg.transport) as session:
            while time.monotonic() < deadline:
                reply = transport.query(session, wire.replay_stats_key(cfg.transport.run_id), b"", 2.0)
                if reply and wire.decode_json(reply)["tables"]["online"]["inserted"] >= 200:
                    break
                time.sleep(0.2)
            assert terminate(group.procs["w1"], grace_s=30) == 0, group.log_tail("w1")
            summary = _summary((tmp_path / "logs" / "w1.log").read_text())
            assert 200 <= summary["env_steps"] < 5_000_000
            time.sleep(0.5)
            reply = transport.query(session, wire.replay_stats_key(cfg.transport.run_id), b"", 2.0)
        # Everything it made before the signal was sent, the last batch too.
        assert wire.decode_json(reply)["tables"]["online"]["inserted"] == summary["env_steps"]
    finally:
        group.stop_all()
