"""The env's spec, computed in a child process of the launcher: ``python -m
laneshift.deploy.spec_process '<{"env.field": value} as JSON>'`` prints ``spec_to_dict`` as JSON;
``SpecProcess`` is the launcher's side of it.

Why a process: the launcher lives as long as the run, and building one env imports highway-env,
gymnasium and pygame (about 80 MB of RSS it would hold to the end for nothing).

Room: deploy, the wiring. May import: the contract, the env actors' package (in the child) and
``deploy.errors``.
"""

from __future__ import annotations

import json
import subprocess
import sys

from laneshift.config import RunConfig, load_run_config

from .errors import LaunchError


class SpecProcess:
    """``main`` in a child process started now; ``result()`` waits and returns the spec as a
    plain dict. A child, not a thread: highway-env, gymnasium and pygame (about 80 MB of RSS) then
    never enter the launcher, which lives as long as the run and counts in its peak memory
    (`laneshift bench run`'s memory per process; docs/performance.md); the child
    runs beside Ray's start, as the thread did."""

    def __init__(self, cfg: RunConfig):
        env = {f"env.{k}": v for k, v in cfg.to_dict()["env"].items()}
        self._proc = subprocess.Popen([sys.executable, "-m", "laneshift.deploy.spec_process", json.dumps(env)],
                                      stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True)

    def result(self) -> dict:
        out, err = self._proc.communicate()
        if self._proc.returncode != 0:
            last = [ln for ln in err.strip().splitlines() if ln.strip()] or ["no output"]
            raise LaunchError(f"the env's spec could not be computed: {last[-1]}")
        return json.loads(out)

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()


def main(argv: list[str]) -> int:
    from laneshift.actors.envs import spec_of  # the child's imports: never the launcher's
    from laneshift.envspec import spec_to_dict

    cfg = load_run_config(overrides=json.loads(argv[0]))
    print(json.dumps(spec_to_dict(spec_of(cfg.env))))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
