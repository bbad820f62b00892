"""The env's spec, computed in a child process of the launcher: ``python -m
laneshift.deploy.spec_process '<{"env.field": value} as JSON>'`` prints ``spec_to_dict`` as JSON.

Why a process: the launcher lives as long as the run, and building one env imports highway-env,
gymnasium and pygame (about 80 MB of RSS it would hold to the end for nothing).

Room: deploy, the wiring. May import: the contract and the env actors' package.
"""

from __future__ import annotations

import json
import sys


def main(argv: list[str]) -> int:
    from laneshift.actors.envs import spec_of
    from laneshift.config import load_run_config
    from laneshift.envspec import spec_to_dict

    cfg = load_run_config(overrides=json.loads(argv[0]))
    print(json.dumps(spec_to_dict(spec_of(cfg.env))))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
