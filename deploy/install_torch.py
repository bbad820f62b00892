"""Install torch 2.13.0, the build this machine should have: the one rule that `make`, the `ray up`
config (deploy/ray-cluster.yaml) and the KubeRay image (deploy/kuberay/Dockerfile) all run.

The rule:

- ``nvidia-smi -L`` lists a GPU: the CUDA build, ``pip install torch==2.13.0`` from pip's own
  index (PyPI's Linux wheel is the CUDA build); the learner then uses the GPU (``learner.device``
  ``auto``).
- otherwise: the CPU build from PyTorch's CPU index (``--index-url
  https://download.pytorch.org/whl/cpu``), when that index answers within a few seconds. When it
  does not, ``pip install torch==2.13.0`` from pip's own index, but only after a ``pip install
  --dry-run`` showed it brings no ``nvidia-*`` package (a machine with a CPU wheel of its own, a
  mirror): PyPI's wheel is the CUDA build, gigabytes of ``nvidia-*`` packages, and is refused
  with one line saying what to set.
- after a CPU install, and with ``--check`` (after the package's own install), any ``nvidia-*``
  package in the environment is an error: "CUDA packages were installed".

It prints one line saying which build it chose and why. Overrides (environment):

- ``LANESHIFT_TORCH=auto|cpu|cuda`` (default ``auto``: the GPU test above);
- ``TORCH_INDEX=URL``: the index the chosen build comes from (default: the CPU index for ``cpu``,
  pip's own index for ``cuda``; e.g. ``https://download.pytorch.org/whl/cu130`` for a CUDA build
  matching an older driver);
- ``LANESHIFT_TORCH_PROBE_S`` (default 10): how long the CPU index may take to answer.

``--dry-run`` prints the choice and the pip commands without running pip (and without asking the
CPU index for more than its torch page). Usage::

    python deploy/install_torch.py [--python PY] [-c constraints.txt] [-q] [--dry-run | --check]

Standard library only, Python 3.8+: it runs before anything is installed, on any node.

Room: deploy (an install script, run before laneshift is installed). May import: the standard library.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import ssl
import subprocess
import sys
import tempfile
import urllib.error
import urllib.parse
import urllib.request

TORCH_VERSION = "2.13.0"
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
CHOICES = ("auto", "cpu", "cuda")
PROG = "install_torch"


class InstallError(Exception):
    """Ends the script with its one-line message and exit code 1."""


def say(message: str) -> None:
    print(f"{PROG}: {message}", flush=True)


def visible_gpu(timeout_s: float = 30.0) -> tuple[str | None, str]:
    """(the first GPU ``nvidia-smi -L`` lists, or None; why) - no nvidia-smi, or one that fails or
    lists no GPU (no driver, no device in this container), means no GPU."""
    exe = shutil.which("nvidia-smi")
    if exe is None:
        return None, "nvidia-smi not found"
    try:
        proc = subprocess.run([exe, "-L"], capture_output=True, text=True, timeout=timeout_s)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f"nvidia-smi -L failed: {exc}"
    gpus = [line.strip() for line in proc.stdout.splitlines() if line.strip().startswith("GPU ")]
    if proc.returncode != 0 or not gpus:
        detail = (proc.stderr or proc.stdout).strip().splitlines()
        return None, f"nvidia-smi -L lists no GPU (exit {proc.returncode}{': ' + detail[0] if detail else ''})"
    return gpus[0], f"nvidia-smi -L lists {gpus[0]}"


def choose() -> tuple[str, str]:
    """('cpu' | 'cuda', why), from LANESHIFT_TORCH or the GPU test."""
    wanted = os.environ.get("LANESHIFT_TORCH", "").strip().lower() or "auto"
    if wanted not in CHOICES:
        raise SystemExit(f"{PROG}: LANESHIFT_TORCH={wanted!r}: expected one of {', '.join(CHOICES)}")
    if wanted != "auto":
        return wanted, f"LANESHIFT_TORCH={wanted}"
    gpu, why = visible_gpu()
    return ("cuda" if gpu else "cpu"), (why if gpu else f"no GPU: {why}")


def index_answers(index: str, timeout_s: float) -> str | None:
    """None when ``index``'s torch page answers, else why not (one line)."""
    url = index.rstrip("/") + "/torch/"
    if urllib.parse.urlsplit(url).scheme == "file":
        path = urllib.request.url2pathname(urllib.parse.urlsplit(url).path)
        return None if os.path.exists(path) else f"{path} does not exist"
    cafile = os.environ.get("PIP_CERT") or None  # the bundle pip is told to trust, if any
    try:
        context = ssl.create_default_context(cafile=cafile)
        with urllib.request.urlopen(url, timeout=timeout_s, context=context) as response:
            response.read(1)
        return None
    except urllib.error.HTTPError as exc:
        return f"HTTP {exc.code} for {url}"
    except urllib.error.URLError as exc:
        return str(getattr(exc.reason, "strerror", None) or exc.reason)
    except (OSError, ValueError) as exc:  # timeouts, resets, a malformed URL
        return str(exc) or type(exc).__name__


def pip(python: str, *args: str) -> list[str]:
    return [python, "-m", "pip", *args]


def nvidia_packages(python: str) -> list[str]:
    """The installed ``nvidia-*`` distributions of ``python``'s environment."""
    proc = subprocess.run(pip(python, "list", "--format=json", "--disable-pip-version-check"),
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise InstallError(f"pip list failed: {proc.stderr.strip()}")
    return sorted(p["name"] for p in json.loads(proc.stdout) if p["name"].lower().startswith("nvidia"))


def check(python: str) -> None:
    found = nvidia_packages(python)
    if found:
        raise InstallError(f"CUDA packages were installed into a CPU environment ({', '.join(found)}): "
                           "start again from a new venv (LANESHIFT_TORCH=cuda if you want the CUDA build)")


def run(cmd: list[str], dry_run: bool) -> None:
    print("+ " + shlex.join(cmd), flush=True)
    if not dry_run and subprocess.run(cmd).returncode != 0:
        raise InstallError(f"failed: {shlex.join(cmd)}")


def precheck_default_index(python: str, install: list[str], dry_run: bool) -> None:
    """Refuse before downloading when pip's own index would bring the CUDA build."""
    with tempfile.TemporaryDirectory() as tmp:
        report = os.path.join(tmp, "report.json")
        preview = pip(python, "install", "--dry-run", "--quiet", "--report", report, *install)
        print("+ " + shlex.join(preview).replace(report, "REPORT.json") + "   # refused if it would install nvidia-* packages",
              flush=True)
        if dry_run:
            return
        proc = subprocess.run(preview)
        if proc.returncode != 0 or not os.path.exists(report):  # an old pip without --report: the guard after
            say("could not preview the install; the nvidia-* check after it stays")
            return
        with open(report) as f:
            would = [item["metadata"]["name"] for item in json.load(f).get("install", [])]
    cuda = sorted(name for name in would if name.lower().startswith("nvidia"))
    if cuda:
        raise InstallError(
            f"pip's own index has torch {TORCH_VERSION} only as the CUDA build ({len(cuda)} nvidia-* packages, "
            f"e.g. {cuda[0]}) and the CPU index cannot be reached: set TORCH_INDEX to a reachable copy of "
            f"{CPU_INDEX}, or LANESHIFT_TORCH=cuda to install the CUDA build")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", default=sys.executable,
                        help="the interpreter whose environment gets torch (default: the one running this)")
    parser.add_argument("-c", "--constraint", action="append", default=[], help="passed to pip install")
    parser.add_argument("-q", "--quiet", action="store_true", help="pip install -q")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--dry-run", action="store_true", help="print the choice and the pip commands; run no pip")
    mode.add_argument("--check", action="store_true",
                      help="install nothing; where the rule picks the CPU build, fail if any nvidia-* package is installed")
    args = parser.parse_args(argv)

    build, why = choose()
    try:
        if args.check:
            if build == "cpu":
                check(args.python)
            return 0
        install = [f"torch=={TORCH_VERSION}", "--disable-pip-version-check"]
        install += [x for c in args.constraint for x in ("-c", c)] + (["-q"] if args.quiet else [])
        index = os.environ.get("TORCH_INDEX", "").strip()
        if build == "cuda":
            source = index or "pip's own index"
            say(f"torch {TORCH_VERSION}, CUDA build from {source} ({why})")
            run(pip(args.python, "install", *install, *(["--index-url", index] if index else [])), args.dry_run)
            return 0
        index = index or CPU_INDEX
        probe_s = float(os.environ.get("LANESHIFT_TORCH_PROBE_S", "10"))
        unreachable = index_answers(index, probe_s)
        if unreachable is None:
            say(f"torch {TORCH_VERSION}, CPU build from {index} ({why})")
            run(pip(args.python, "install", *install, "--index-url", index), args.dry_run)
        else:
            say(f"torch {TORCH_VERSION}, CPU build wanted ({why}), but {index} cannot be reached ({unreachable}): "
                "from pip's own index instead, refused if that brings nvidia-* packages")
            precheck_default_index(args.python, install, args.dry_run)
            run(pip(args.python, "install", *install), args.dry_run)
        if args.dry_run:
            print("+ " + shlex.join(pip(args.python, "list", "--format=json")) + "   # error if any nvidia-* package",
                  flush=True)
        else:
            check(args.python)
        return 0
    except InstallError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr, flush=True)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
