"""``deploy/ray-cluster.yaml``, the ``ray up`` config: Ray 2.60's own config code accepts it, and its
commands do what the file says (token auth, torch by deploy/install_torch.py, the autoscaler,
laneshift's custom resources). The commands run here in bash against stand-ins for ``ray``, ``pip``
and the venv's ``python`` that only record what they got, or with the install script's --dry-run,
so no Ray is started and nothing is installed.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import socket
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

# Importing Ray's CLI (for its `ray start` parser) warns about Ray Serve's pydantic use.
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "deploy" / "ray-cluster.yaml"
INSTALL_TORCH = "~/laneshift-install_torch.py"  # deploy/install_torch.py on every node (file_mounts)


@pytest.fixture(scope="module")
def raw() -> dict:
    return yaml.safe_load(CONFIG.read_text())


@pytest.fixture(scope="module")
def prepared(raw) -> dict:
    from ray.autoscaler._private.util import prepare_config, validate_config

    config = prepare_config(raw)
    validate_config(config)
    return config


def _run_like_ray_up(cmd: str, home: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run one command the way ray up's SSH command runner does: ssh joins its words into one line
    for the remote login shell, which runs ``bash --login -c -i 'source ~/.bashrc; ... (cmd)'``."""
    from ray.autoscaler._private.command_runner import _with_interactive

    full_env = {"PATH": os.environ["PATH"], "HOME": str(home), "RAY_HEAD_IP": "10.0.0.1", **(env or {})}
    return subprocess.run(["/bin/sh", "-c", " ".join(_with_interactive(cmd))], env=full_env, cwd=home, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=60)


def _stand_in(home: Path, name: str, body: str) -> Path:
    """An executable ~/laneshift-venv/bin/<name> running ``body`` (Python) with sys.argv."""
    path = home / "laneshift-venv" / "bin" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"#!{sys.executable}\nimport json, os, sys\n{body}\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _ray_start_args(cmd: str, tmp_path: Path) -> tuple[list[str], dict]:
    """What `ray start` receives from ``cmd`` in ray up's shell, and the environment it runs in."""
    _stand_in(tmp_path, "ray", "json.dump({'argv': sys.argv[1:], 'env': dict(os.environ)},"
                               " open(os.path.expanduser('~/ray-call.json'), 'w'))")
    proc = _run_like_ray_up(cmd, tmp_path)
    assert proc.returncode == 0, proc.stderr
    call = json.loads((tmp_path / "ray-call.json").read_text())
    return call["argv"], call["env"]


def _parse_ray_start(argv: list[str]) -> dict:
    """Ray 2.60's own `ray start` option parser (click), without running the command."""
    from ray.scripts.scripts import start

    assert argv[0] == "start", argv
    return start.make_context("start", list(argv[1:])).params


def test_ray_accepts_the_config(prepared):
    # The local provider: one internal node type for head and workers, every listed IP started.
    assert prepared["provider"]["type"] == "local"
    assert prepared["head_node_type"] in prepared["available_node_types"]
    assert prepared["max_workers"] == len(prepared["provider"]["worker_ips"])


def test_placeholders_are_marked(raw):
    assert raw["provider"]["head_ip"] == "HEAD_IP"
    assert all(ip.startswith("WORKER_IP") for ip in raw["provider"]["worker_ips"])
    text = CONFIG.read_text()
    assert "REPLACE" in text and "cloud" in text.lower()


def test_head_starts_the_autoscaler_with_dashboard_and_laneshift_resources(raw, tmp_path):
    cmd = raw["head_start_ray_commands"][-1]
    # Without it the autoscaler never starts the listed workers.
    assert "--autoscaling-config=~/ray_bootstrap_config.yaml" in cmd
    argv, env = _ray_start_args(cmd, tmp_path)
    params = _parse_ray_start(argv)
    assert params["head"] is True
    assert params["port"] == 6379
    assert params["dashboard_host"] == "0.0.0.0"
    assert params["dashboard_port"] == 8265
    assert params["autoscaling_config"] == "~/ray_bootstrap_config.yaml"  # Ray expands the ~ itself
    assert json.loads(params["resources"]) == {"laneshift_replay": 1, "laneshift_learner": 1}
    assert env["RAY_AUTH_MODE"] == "token"
    assert "OMP_NUM_THREADS" not in env  # each actor gets its num_cpus, not ray up's 1


def test_workers_join_the_head_with_token_auth(raw, tmp_path):
    argv, env = _ray_start_args(raw["worker_start_ray_commands"][-1], tmp_path)
    params = _parse_ray_start(argv)
    assert params["head"] is False
    assert params["address"] == "10.0.0.1:6379"
    resources = json.loads(params["resources"])
    # One per CPU: `nproc`, run after ray up's OMP_NUM_THREADS=1 is unset (nproc honours it).
    assert set(resources) == {"laneshift_env"} and resources["laneshift_env"] == len(os.sched_getaffinity(0))
    # `ray start --address` does not turn token auth on by itself (only a head with a token does).
    assert env["RAY_AUTH_MODE"] == "token"


def test_every_node_gets_the_token_and_token_mode(raw, tmp_path):
    mounts = raw["file_mounts"]
    assert mounts["~/.ray/auth_token"] == "~/.ray/auth_token"  # Ray's default token path, same on both ends
    setup = raw["setup_commands"]
    # Every later shell (ray up's, `ray attach`) has RAY_AUTH_MODE=token, written once only.
    for _ in range(2):
        proc = _run_like_ray_up(setup[0], tmp_path)
        assert proc.returncode == 0, proc.stderr
    assert (tmp_path / ".bashrc").read_text().splitlines() == ["export RAY_AUTH_MODE=token"]
    # The token check fails the setup when the token did not arrive, and passes once it is there.
    check = next(c for c in setup if "auth_token" in c)
    assert _run_like_ray_up(check, tmp_path).returncode != 0
    token = tmp_path / ".ray" / "auth_token"
    token.parent.mkdir()
    token.write_text("0123456789abcdef")
    assert _run_like_ray_up(check, tmp_path).returncode == 0
    assert stat.S_IMODE(token.stat().st_mode) == 0o600


def _with_install_script(raw: dict, home: Path) -> None:
    """What ray up's file_mounts put on a node: the install rule and the tested versions."""
    mounts = raw["file_mounts"]
    assert mounts[INSTALL_TORCH] == "deploy/install_torch.py"
    assert mounts["~/laneshift-constraints.txt"] == "constraints.txt"
    shutil.copy(ROOT / mounts[INSTALL_TORCH], home / INSTALL_TORCH.removeprefix("~/"))


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_torch_comes_by_the_install_rule_before_laneshift(raw, tmp_path):
    setup = raw["setup_commands"]
    torch_i = next(i for i, c in enumerate(setup) if INSTALL_TORCH in c and "--check" not in c)
    laneshift_i = next(i for i, c in enumerate(setup) if "laneshift[cluster]" in c)
    assert laneshift_i > torch_i
    # laneshift's own install keeps the same torch pinned, at the tested versions, so pip keeps the build.
    argv = shlex.split(setup[laneshift_i])
    assert "torch==2.13.0" in argv and argv[argv.index("-c") + 1] == "~/laneshift-constraints.txt"
    # The rule itself is tests/test_install_rule.py's; here: it runs in ray up's shell, into the node's venv.
    _with_install_script(raw, tmp_path)
    venv_python = tmp_path / "laneshift-venv" / "bin" / "python"
    gpu = _run_like_ray_up(setup[torch_i] + " --dry-run", tmp_path, env={"LANESHIFT_TORCH": "cuda"})
    assert gpu.returncode == 0, gpu.stderr
    assert "CUDA build" in gpu.stdout and f"+ {venv_python} -m pip install torch==2.13.0" in gpu.stdout
    no_index = {"LANESHIFT_TORCH": "cpu", "TORCH_INDEX": f"http://127.0.0.1:{_closed_port()}/whl/cpu"}
    cpu = _run_like_ray_up(setup[torch_i] + " --dry-run", tmp_path, env=no_index)
    assert cpu.returncode == 0, cpu.stderr
    assert "cannot be reached" in cpu.stdout and f"{tmp_path}/laneshift-constraints.txt" in cpu.stdout


def test_laneshift_wheel_is_the_projects_version(raw):
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    wheel = f"laneshift-{version}-py3-none-any.whl"  # what `pip wheel --no-deps --wheel-dir .whl .` makes
    installs = [c for c in raw["setup_commands"] if "laneshift-wheels" in c]
    assert len(installs) == 2 and all(wheel in c for c in installs), "the wheel's name follows pyproject's version"
    # The re-install of a rebuilt wheel must not pull dependencies (torch from PyPI is the CUDA build).
    assert "--no-deps" in shlex.split(installs[1]) and "--force-reinstall" in shlex.split(installs[1])
    assert raw["file_mounts"]["~/laneshift-wheels"] == ".whl"


CPU_LISTING = [{"name": "torch", "version": "2.13.0+cpu"}, {"name": "ray", "version": "2.60.0"}]
CUDA_LISTING = [{"name": "torch", "version": "2.13.0"}, {"name": "nvidia-cublas-cu12", "version": "12.8.4.1"}]


@pytest.mark.parametrize("build, listing, ok", [("cpu", CPU_LISTING, True), ("cpu", CUDA_LISTING, False),
                                                 ("cuda", CUDA_LISTING, True)])
def test_setup_fails_when_cuda_packages_came_into_a_cpu_node(raw, tmp_path, build, listing, ok):
    check = next(c for c in raw["setup_commands"] if INSTALL_TORCH in c and "--check" in c)
    _with_install_script(raw, tmp_path)
    _stand_in(tmp_path, "python", f"assert sys.argv[1:4] == ['-m', 'pip', 'list'], sys.argv\nprint({json.dumps(listing)!r})")
    proc = _run_like_ray_up(check, tmp_path, env={"LANESHIFT_TORCH": build})
    assert (proc.returncode == 0) is ok, proc.stderr
    assert ok or "CUDA packages were installed" in proc.stderr
