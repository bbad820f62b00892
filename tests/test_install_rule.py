"""The install rule: which torch build ``deploy/install_torch.py`` installs, the script
that ``make``, ``deploy/ray-cluster.yaml`` and the KubeRay Dockerfile all run, and what the package
declares (``pyproject.toml``'s ranges against ``constraints.txt``'s tested set; the environments
without torch, Ray, zenoh or FastAPI).

The script runs as a subprocess with ``PATH`` holding only a folder of stand-ins: a fake
``nvidia-smi`` that lists a GPU (or fails, or is absent), and a fake interpreter that answers its
``python -m pip`` calls and records them, so nothing is installed. The CPU index is a local HTTP
server or a closed local port (``TORCH_INDEX``); no other network.

Room: tests, unit. May import: laneshift (any floor), pytest, packaging, the standard library and
what the code under test needs.
"""

from __future__ import annotations

import http.server
import importlib.metadata
import json
import os
import re
import shlex
import socket
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "deploy" / "install_torch.py"
CONSTRAINTS = ROOT / "constraints.txt"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
GPU_LINE = "GPU 0: NVIDIA H100 80GB HBM3 (UUID: GPU-0b8a3a4e-1f2d-4c55-9a8e-000000000000)"


# ---------------------------------------------------------------------------- stand-ins


@pytest.fixture
def bin_dir(tmp_path: Path) -> Path:
    """The only folder on the script's PATH (so a real nvidia-smi is never found)."""
    path = tmp_path / "bin"
    path.mkdir()
    return path


def fake_nvidia_smi(bin_dir: Path, stdout: str, code: int = 0, stderr: str = "") -> None:
    exe = bin_dir / "nvidia-smi"
    exe.write_text(f"#!/bin/sh\nprintf '%s' {shlex.quote(stdout)}\nprintf '%s' {shlex.quote(stderr)} >&2\nexit {code}\n")
    exe.chmod(0o755)


def fake_python(tmp_path: Path, *, listing: list[str] = (), would: list[str] = ()) -> tuple[Path, Path]:
    """An interpreter for ``--python``: ``-m pip list`` prints ``listing``; ``-m pip install
    --dry-run --report F`` writes a report that would install ``would``; other pip installs succeed.
    Returns it and the file its calls are recorded in (one JSON argv a line)."""
    log = tmp_path / "pip-calls.jsonl"
    exe = tmp_path / "fake-python"
    exe.write_text(
        f"#!{sys.executable}\nimport json, sys\n"
        f"args = sys.argv[1:]\nopen({str(log)!r}, 'a').write(json.dumps(args) + '\\n')\n"
        "assert args[:2] == ['-m', 'pip'], args\n"
        f"if args[2] == 'list':\n    print(json.dumps([{{'name': n, 'version': '1'}} for n in {list(listing)!r}]))\n"
        "elif '--dry-run' in args:\n"
        f"    json.dump({{'install': [{{'metadata': {{'name': n}}}} for n in {list(would)!r}]}},"
        " open(args[args.index('--report') + 1], 'w'))\n")
    exe.chmod(0o755)
    return exe, log


def calls(log: Path) -> list[list[str]]:
    return [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def local_index():
    """A stand-in for PyTorch's CPU index on 127.0.0.1: its torch page answers, nothing else does."""

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 (http.server's name)
            ok = self.path == "/whl/cpu/torch/"
            self.send_response(200 if ok else 404)
            self.end_headers()
            self.wfile.write(b"<a href='torch-2.13.0+cpu-cp311-cp311-linux_x86_64.whl'>torch</a>" if ok else b"")

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}/whl/cpu"
    server.shutdown()
    server.server_close()
    thread.join()


def install_torch(bin_dir: Path, *args: str, python: Path | None = None, **env: str) -> subprocess.CompletedProcess:
    """deploy/install_torch.py with ``PATH=bin_dir`` and ``env`` (LANESHIFT_TORCH, TORCH_INDEX, ...)."""
    base = {k: v for k, v in os.environ.items() if k not in {"LANESHIFT_TORCH", "TORCH_INDEX", "PATH"}}
    argv = [sys.executable, str(SCRIPT), "--python", str(python or "PY"), *args]
    return subprocess.run(argv, env={**base, "PATH": str(bin_dir), "LANESHIFT_TORCH_PROBE_S": "5", **env},
                          capture_output=True, text=True, timeout=60)


def plan(proc: subprocess.CompletedProcess) -> tuple[str, list[str]]:
    """(the choice line, the commands it would run) of a --dry-run."""
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("install_torch: torch 2.13.0, "), proc.stdout
    return lines[0], [line.removeprefix("+ ") for line in lines[1:]]


# ---------------------------------------------------------------------------- the choice (dry runs)


def test_a_visible_gpu_gets_the_cuda_build_from_pips_own_index(bin_dir):
    fake_nvidia_smi(bin_dir, GPU_LINE + "\n")
    choice, commands = plan(install_torch(bin_dir, "--dry-run", "-q", "-c", "constraints.txt"))
    assert choice == f"install_torch: torch 2.13.0, CUDA build from pip's own index (nvidia-smi -L lists {GPU_LINE})"
    # PyPI's torch 2.13.0 (the CUDA build), and no nvidia-* guard: those packages are the point.
    assert commands == ["PY -m pip install torch==2.13.0 --disable-pip-version-check -c constraints.txt -q"]


def test_no_gpu_gets_the_cpu_build_from_the_cpu_index(bin_dir, local_index):
    choice, commands = plan(install_torch(bin_dir, "--dry-run", TORCH_INDEX=local_index))
    assert choice == f"install_torch: torch 2.13.0, CPU build from {local_index} (no GPU: nvidia-smi not found)"
    assert commands[0] == f"PY -m pip install torch==2.13.0 --disable-pip-version-check --index-url {local_index}"
    assert commands[1].startswith("PY -m pip list --format=json") and "nvidia" in commands[1]  # the guard after
    assert len(commands) == 2


@pytest.mark.parametrize("stdout, code, stderr", [
    ("", 9, "NVIDIA-SMI has failed because it couldn't communicate with the NVIDIA driver."),  # driver not loaded
    ("No devices found.\n", 6, ""),
    ("", 0, ""),  # runs, lists nothing (a container without a device)
])
def test_an_nvidia_smi_that_lists_no_gpu_means_the_cpu_build(bin_dir, local_index, stdout, code, stderr):
    fake_nvidia_smi(bin_dir, stdout, code, stderr)
    choice, commands = plan(install_torch(bin_dir, "--dry-run", TORCH_INDEX=local_index))
    assert f"CPU build from {local_index} (no GPU: nvidia-smi -L lists no GPU (exit {code}" in choice
    assert f"--index-url {local_index}" in commands[0]


@pytest.mark.parametrize("unreachable", ["closed port", "no torch page"])
def test_an_unreachable_cpu_index_falls_back_to_pips_own_index_guarded(bin_dir, local_index, unreachable):
    index = f"http://127.0.0.1:{closed_port()}/whl/cpu" if unreachable == "closed port" else local_index + "/nothing"
    choice, commands = plan(install_torch(bin_dir, "--dry-run", "-c", "constraints.txt", TORCH_INDEX=index))
    assert choice.startswith(f"install_torch: torch 2.13.0, CPU build wanted (no GPU: nvidia-smi not found), "
                             f"but {index} cannot be reached (")
    assert choice.endswith("from pip's own index instead, refused if that brings nvidia-* packages")
    assert "HTTP 404" in choice if unreachable == "no torch page" else "refused" in choice.lower()
    # A preview first (refused if it would bring nvidia-* packages), then the install, then the guard.
    assert commands[0].startswith("PY -m pip install --dry-run --quiet --report REPORT.json torch==2.13.0")
    assert commands[1] == "PY -m pip install torch==2.13.0 --disable-pip-version-check -c constraints.txt"
    assert commands[2].startswith("PY -m pip list --format=json")


def test_overrides(bin_dir, local_index):
    fake_nvidia_smi(bin_dir, GPU_LINE + "\n")
    choice, commands = plan(install_torch(bin_dir, "--dry-run", LANESHIFT_TORCH="cpu", TORCH_INDEX=local_index))
    assert choice.endswith("(LANESHIFT_TORCH=cpu)") and f"--index-url {local_index}" in commands[0]
    (bin_dir / "nvidia-smi").unlink()
    cu = "https://download.pytorch.org/whl/cu130"  # printed only: a dry run asks no index for the CUDA build
    choice, commands = plan(install_torch(bin_dir, "--dry-run", LANESHIFT_TORCH="cuda", TORCH_INDEX=cu))
    assert choice == f"install_torch: torch 2.13.0, CUDA build from {cu} (LANESHIFT_TORCH=cuda)"
    assert commands == [f"PY -m pip install torch==2.13.0 --disable-pip-version-check --index-url {cu}"]
    bad = install_torch(bin_dir, "--dry-run", LANESHIFT_TORCH="rocm")
    assert bad.returncode != 0 and "LANESHIFT_TORCH='rocm': expected one of auto, cpu, cuda" in bad.stderr


def test_the_default_cpu_index_is_pytorchs():
    from laneshift.deploy import install_torch as script  # the same file, importable (standard library only)

    assert script.CPU_INDEX == "https://download.pytorch.org/whl/cpu"


# ---------------------------------------------------------------------------- real runs against a fake pip


def test_fallback_refuses_the_cuda_build_before_downloading_it(bin_dir, tmp_path):
    python, log = fake_python(tmp_path, would=["torch", "nvidia-cublas-cu12", "nvidia-cudnn-cu12", "sympy"])
    proc = install_torch(bin_dir, python=python, TORCH_INDEX=f"http://127.0.0.1:{closed_port()}/whl/cpu")
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [
        "install_torch: error: pip's own index has torch 2.13.0 only as the CUDA build (2 nvidia-* packages, "
        "e.g. nvidia-cublas-cu12) and the CPU index cannot be reached: set TORCH_INDEX to a reachable copy of "
        "https://download.pytorch.org/whl/cpu, or LANESHIFT_TORCH=cuda to install the CUDA build"]
    assert [c for c in calls(log) if "--dry-run" not in c] == []  # nothing was installed


def test_fallback_installs_a_cpu_wheel_that_pips_own_index_has(bin_dir, tmp_path):
    """This machine's case: the CPU index is out of reach, and pip's configuration has a CPU wheel."""
    python, log = fake_python(tmp_path, would=["torch", "sympy"], listing=["torch", "sympy"])
    proc = install_torch(bin_dir, "-c", "constraints.txt", python=python,
                         TORCH_INDEX=f"http://127.0.0.1:{closed_port()}/whl/cpu")
    assert proc.returncode == 0, proc.stderr
    got = calls(log)
    assert [c[2:4] for c in got] == [["install", "--dry-run"], ["install", "torch==2.13.0"], ["list", "--format=json"]]
    assert "--index-url" not in got[1] and got[1][-2:] == ["-c", "constraints.txt"]


def test_a_cpu_install_that_brought_cuda_packages_fails(bin_dir, tmp_path, local_index):
    python, log = fake_python(tmp_path, listing=["torch", "nvidia-nccl-cu12"])
    proc = install_torch(bin_dir, python=python, TORCH_INDEX=local_index)
    assert proc.returncode == 1
    assert "CUDA packages were installed into a CPU environment (nvidia-nccl-cu12)" in proc.stderr
    assert calls(log)[0][2:] == ["install", "torch==2.13.0", "--disable-pip-version-check", "--index-url", local_index]


@pytest.mark.parametrize("gpu, listing, ok", [
    (False, ["torch", "ray"], True),
    (False, ["torch", "nvidia-cublas-cu12"], False),
    (True, ["torch", "nvidia-cublas-cu12"], True),  # the CUDA build was chosen: its packages belong
])
def test_check_guards_only_where_the_cpu_build_was_chosen(bin_dir, tmp_path, gpu, listing, ok):
    if gpu:
        fake_nvidia_smi(bin_dir, GPU_LINE + "\n")
    python, log = fake_python(tmp_path, listing=listing)
    proc = install_torch(bin_dir, "--check", python=python)
    assert (proc.returncode == 0) is ok, proc.stderr
    assert [c[2] for c in calls(log)] == ([] if gpu else ["list"])


# ---------------------------------------------------------------------------- who runs it, what the package declares


def test_make_the_cluster_config_and_the_image_all_run_the_rule():
    makefile = (ROOT / "Makefile").read_text()
    venv_rule = makefile.split("$(STAMP): ", 1)[1].split("\n\n", 1)[0]
    lines = [line.strip() for line in venv_rule.splitlines() if not line.strip().startswith("#")]
    torch_i = lines.index("$(PY) deploy/install_torch.py -q -c constraints.txt")
    package_i = next(i for i, line in enumerate(lines) if "-e \".[" in line)
    assert torch_i < package_i and "-c constraints.txt" in lines[package_i]
    assert lines[package_i + 1] == "@$(PY) deploy/install_torch.py --check"
    dockerfile = (ROOT / "deploy" / "kuberay" / "Dockerfile").read_text()
    assert "RUN python install_torch.py -c constraints.txt" in dockerfile and "python install_torch.py --check" in dockerfile
    cluster = (ROOT / "deploy" / "ray-cluster.yaml").read_text()
    assert "~/laneshift-install_torch.py: deploy/install_torch.py" in cluster
    # Nowhere a torch install of its own any more (docs/deploy.md names the rule too).
    for text in (makefile, dockerfile, cluster):
        assert not re.search(r"pip install [^\n]*torch==[\d.]+ --index-url", text)
    assert not re.search(r"^\t\S*pip install [^\n]*-q torch==", makefile, re.M)


def _pins() -> dict[str, str]:
    pins = {}
    for line in CONSTRAINTS.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            pins[canonicalize_name(name)] = version.strip()
    return pins


def test_every_dependency_has_a_range_and_a_tested_pin_inside_it():
    from laneshift.deploy import install_torch as script

    project = PYPROJECT["project"]
    reqs = [Requirement(r) for r in project["dependencies"]]
    reqs += [Requirement(r) for extra in project["optional-dependencies"].values() for r in extra]
    reqs = [r for r in reqs if r.name != "laneshift"]
    pins = _pins()
    assert pins["torch"] == script.TORCH_VERSION
    for req in reqs:
        assert "==" not in str(req.specifier), f"{req}: a range, not a pin (the pin is constraints.txt's)"
        assert canonicalize_name(req.name) in pins, f"{req.name} has no tested version in constraints.txt"
        assert req.specifier.contains(pins[canonicalize_name(req.name)]), f"{pins[canonicalize_name(req.name)]} outside {req}"
    assert "pygame" not in pins and all(r.name != "pygame" for r in reqs)  # highway-env brings pygame-ce


ENVS_ALONE = """
import importlib.abc, sys
HEAVY = {"torch", "ray", "zenoh", "fastapi", "uvicorn", "minari", "safetensors", "tensorboardX", "tensorboard",
         "prometheus_client"}
class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in HEAVY:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, NotInstalled())
import gymnasium as gym
import laneshift.actors.envs
env = gym.make("laneshift.actors:laneshift/StraightLaneChange-v0")
env.reset(seed=0)
env.step(env.action_space.sample())
print("ok")
"""


def test_the_environments_need_no_training_dependency():
    """What the core install (no extra) holds is enough for the environments."""
    core = {canonicalize_name(Requirement(r).name) for r in PYPROJECT["project"]["dependencies"]}
    assert core == {"numpy", "gymnasium", "highway-env", "pyyaml", "matplotlib"}
    proc = subprocess.run([sys.executable, "-c", ENVS_ALONE], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_version_license_and_authors():
    import laneshift

    assert laneshift.__version__ == importlib.metadata.version("laneshift") == PYPROJECT["project"]["version"]
    assert PYPROJECT["project"]["license"] == "MIT" and PYPROJECT["project"]["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "Copyright (c) 2026 the laneshift authors" in text
    assert PYPROJECT["project"]["authors"] == [{"name": "the laneshift authors"}]


def test_the_command_without_the_train_extra_says_what_to_install():
    """A core-only install (the environments) runs `laneshift` into one line naming the extra."""
    blocker = ("import sys\n"
               "class Block:\n"
               "    def find_spec(self, name, path=None, target=None):\n"
               "        top = name.split('.')[0]\n"
               "        if top in ('tqdm', 'zenoh', 'torch', 'ray'):\n"
               "            raise ModuleNotFoundError(f'No module named {top!r}', name=top)\n"
               "sys.meta_path.insert(0, Block())\n"
               "from laneshift.tools.cli import main\n"
               "raise SystemExit(main(['--help']))\n")
    proc = subprocess.run([sys.executable, "-c", blocker], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "needs the train extra" in proc.stderr and "laneshift[train]" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
