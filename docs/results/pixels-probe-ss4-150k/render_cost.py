"""What anti-aliased frames cost the env: grayscale env steps per second at env.frame_supersample 1, 2
and 4 (k x k drawn pixels per frame pixel), random actions on the straight road, alternating the factors
round by round in one process (A B C A B C) so that the machine's drift falls on all of them.

    python render_cost.py [--steps 1000] [--rounds 3]

Room: a study script (docs/results). May import: anything in laneshift, numpy.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from laneshift.actors.envs import make_env


def steps_per_s(env, rng: np.random.Generator, steps: int) -> float:
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(int(rng.integers(9)))
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - t0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=1000)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--factors", default="1,2,4")
    args = p.parse_args()
    factors = [int(k) for k in args.factors.split(",")]
    envs = {k: make_env("straight", observation="grayscale", frame_supersample=k) for k in factors}
    for k, env in envs.items():
        env.reset(seed=0)
        steps_per_s(env, np.random.default_rng(0), 50)  # warm-up: the renderer and its surface
    rates: dict[int, list[float]] = {k: [] for k in factors}
    for r in range(args.rounds):
        for k in factors:
            rates[k].append(steps_per_s(envs[k], np.random.default_rng(r), args.steps))
    for k in factors:
        print(json.dumps({"frame_supersample": k, "env_steps_per_s": [round(x, 1) for x in rates[k]],
                          "ms_per_step": round(1e3 * args.rounds / sum(rates[k]), 3)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
