"""The documentation a third party relies on, checked against the code, so it cannot drift from it.

What it is: docs/wire.md §12's commands run as written (a router and a standalone replay server
as subprocesses, then docs/examples/foreign_client.py against them), and docs/wire.md's stated
facts that a client has to trust (the hex example's sizes, kind 7 on a transitions key, the
required "arrays" list, the replay/info key).
Room: tests, unit. May import: the standard library, pytest, httpx, numpy and laneshift (the encoder and core the
docs describe); the example itself is run as a separate process and must import no laneshift.
Every process this file starts is ended by its own PID.
"""

from __future__ import annotations

import ast
import json
import re
import shlex
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.deploy.processes import terminate
from laneshift.replay_server.core import ReplayCore

ROOT = Path(__file__).resolve().parents[1]
WIRE_MD = ROOT / "docs" / "wire.md"
EXAMPLE = ROOT / "docs" / "examples" / "foreign_client.py"
DOC_ENDPOINT, DOC_RUN_DIR = "tcp/127.0.0.1:7447", "runs/replay-only"


def documented_commands(port: int, run_dir: Path) -> list[list[str]]:
    """docs/wire.md §12's command block, with a free port and a temp run dir put in."""
    block = WIRE_MD.read_text().split("<!-- standalone-commands -->", 1)[1].split("```bash\n", 1)[1]
    block = block.split("```", 1)[0].replace("\\\n", " ")
    commands = []
    for line in filter(str.strip, block.splitlines()):
        argv = [a.replace(DOC_ENDPOINT, f"tcp/127.0.0.1:{port}").replace(DOC_RUN_DIR, str(run_dir))
                for a in shlex.split(line) if a != "&"]
        # `laneshift` is this interpreter's (the console script runs `python -m laneshift` too).
        commands.append({"laneshift": [sys.executable, "-m", "laneshift"], "python": [sys.executable]}[argv[0]]
                        + argv[1:])
    return commands


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(path: Path, procs: dict[str, subprocess.Popen], logs: Path, timeout_s: float) -> dict:
    """The ready file's JSON once it parses (it is written in place, §12); fails early if a process died."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for name, proc in procs.items():
            if proc.poll() is not None:
                pytest.fail(f"{name} exited with {proc.returncode}:\n{(logs / f'{name}.log').read_text()}")
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            time.sleep(0.2)
    pytest.fail(f"no ready file {path} after {timeout_s} s:\n{(logs / 'replay-server.log').read_text()}")


def test_foreign_client_against_a_standalone_replay_server(tmp_path):
    run_dir = tmp_path / "replay-only"
    router_cmd, server_cmd, client_cmd = documented_commands(free_port(), run_dir)
    assert router_cmd[3] == "router" and server_cmd[3] == "replay-server"
    assert client_cmd[1] == str(EXAMPLE.relative_to(ROOT))
    procs: dict[str, subprocess.Popen] = {}
    try:
        for name, cmd in (("router", router_cmd), ("replay-server", server_cmd)):
            with open(tmp_path / f"{name}.log", "w") as log:
                procs[name] = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
        ready = wait_ready(run_dir / "ready.json", procs, tmp_path, timeout_s=180)
        assert set(ready) == {"pid", "time", "http_port"} and ready["pid"] == procs["replay-server"].pid
        assert isinstance(ready["http_port"], int) and ready["http_port"] > 0 and abs(ready["time"] - time.time()) < 300

        client = subprocess.run(client_cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert client.returncode == 0, client.stdout + client.stderr
        assert client.stdout.splitlines()[-1] == "ok"

        with httpx.Client(base_url=f"http://127.0.0.1:{ready['http_port']}", timeout=10) as http:
            info = http.get("/info").json()
            assert info["http_url"] == f"http://127.0.0.1:{ready['http_port']}" and info["run_id"] == "run"
            assert f"replay/info: {info!r}" in client.stdout  # the zenoh queryable said the same
            stats = http.get("/stats").json()
            assert stats["actors"]["foreign0"]["stored"] == 8 and stats["actors"]["foreign0"]["lost_batches"] == 0
            assert stats["rejected"] == {"wrong_kind": 1, "bad_request:bad_header": 1}
            assert (stats["obs_shape"], stats["obs_dtype"], stats["n_actions"]) == (
                info["obs_shape"], info["obs_dtype"], info["n_actions"])
            metrics = http.get("/metrics").text
            assert 'laneshift_replay_sample_duration_seconds_count{result="batch"} 1.0' in metrics
            assert 'laneshift_replay_sample_duration_seconds_count{result="error"} 1.0' in metrics
            assert "\nprocess_resident_memory_bytes " in metrics
        log = (tmp_path / "replay-server.log").read_text()
        assert f"HTTP inspection API on http://127.0.0.1:{ready['http_port']} " in log

        # §12: stop the server before its router; it exits 0 with its final stats written.
        assert terminate(procs["replay-server"], 60) == 0, (tmp_path / "replay-server.log").read_text()
        final = json.loads((run_dir / "replay_stats.json").read_text())
        assert final["tables"]["online"]["inserted"] == 8
        assert terminate(procs["router"], 30) == 0
    finally:
        for proc in reversed(procs.values()):  # the server before its router (§12)
            terminate(proc, 10)


def test_the_example_imports_no_laneshift_code():
    tree = ast.parse(EXAMPLE.read_text())
    imported = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
                for alias in node.names}
    imported |= {node.module.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported - {"__future__"} <= set(sys.stdlib_module_names) | {"zenoh"}, imported
    assert EXAMPLE.read_text().startswith('"""') and "May import:" in EXAMPLE.read_text().split('"""')[1]


# --------------------------------------------------------------------------- docs/wire.md's stated facts


def hex_example_batch() -> bytes:
    return wire.encode_transitions(wire.TransitionBatch.from_arrays(
        actor="w0", seq=3, weights_version=7, phase=0, env_steps=128, obs=np.array([[0.5, -1.0]], np.float32),
        action=[4], reward=[1.0], next_obs=np.array([[0.25, 2.0]], np.float32), terminated=[0], truncated=[1]))


def test_hex_example_sizes_are_what_the_encoder_writes():
    """tests/test_wire.py compares the hex dump byte for byte; here the sizes the text states."""
    text = WIRE_MD.read_text().split("## 9.", 1)[1].split("## 10.", 1)[0]
    msg = hex_example_batch()
    hlen = int.from_bytes(msg[8:12], "little")
    total, header, arrays = map(int, re.search(
        r"(\d+) bytes \(`xxd -g1`; 12 envelope \+ (\d+) header \+ (\d+) array bytes\)", text).groups())
    assert (total, header, arrays) == (len(msg), hlen, len(msg) - 12 - hlen)
    assert f"header length {hlen}" in text and f"the {hlen}-byte JSON header" in text
    terms = re.search(r"Total `([0-9 +]+) = (\d+)` bytes", text)
    assert sum(map(int, terms.group(1).split("+"))) == int(terms.group(2)) == len(msg)
    assert f"`0x00c-0x{12 + hlen - 1:03x}`" in text and f"`0x{len(msg) - 1:03x}` | `steps`" in text


SCHEMA = wire.TransitionSchema(obs_shape=(2,), obs_dtype="float32", n_actions=9)


def test_kind_7_on_a_transitions_key_is_wrong_kind_and_8_is_bad_kind():
    core = ReplayCore(ReplayConfig(capacity=10, min_size=1), SCHEMA)
    prio = wire.encode_priorities(wire.PriorityUpdate(np.array([0]), np.array([0], np.uint8),
                                                      np.array([1.0], np.float32)))
    assert prio[6] == 7 and core.ingest(prio, "w0") == "wrong_kind"
    assert core.ingest(prio[:6] + b"\x08" + prio[7:], "w0") == "bad_kind"
    assert core.ingest(hex_example_batch(), "w0") is None  # and the §9 message is accepted as it stands
    assert core.stats()["rejected"] == {"wrong_kind": 1, "bad_kind": 1}


def test_header_only_messages_still_need_an_arrays_list():
    core = ReplayCore(ReplayConfig(capacity=10, min_size=1, samples_per_insert=0.0), SCHEMA)
    assert core.ingest(hex_example_batch(), "w0") is None
    fields = {"batch_size": 1, "num_batches": 1, "min_version": -1}
    for header, kind in ((fields, wire.Kind.ERROR), ({**fields, "arrays": []}, wire.Kind.BATCH)):
        head = json.dumps(header).encode()
        request = b"LSHF" + (2).to_bytes(2, "little") + bytes([3, 0]) + len(head).to_bytes(4, "little") + head
        reply = core.handle_sample_query(request)
        assert wire.peek_kind(reply) == kind
    assert wire.decode_error(core.handle_sample_query(b"LSHF")).reason == "bad_request"  # §5.3: folded
    assert core.stats()["rejected"] == {"bad_request:bad_header": 1, "bad_request:truncated": 1}


def test_replay_info_key():
    assert wire.replay_info_key("r1") == "laneshift/r1/replay/info"
    for bad in ("", "a/b", "*", "x" * 65):
        with pytest.raises(ValueError):
            wire.replay_info_key(bad)
    assert "| `laneshift/<run>/replay/info` | queryable | replay server |" in WIRE_MD.read_text()
