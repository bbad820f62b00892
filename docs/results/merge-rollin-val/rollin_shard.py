"""Demonstrations from where a network drives (DAgger's idea, Ross et al. 2011): a trained network
drives the first steps of each episode, then the scripted driver takes over and only its part is
recorded.

Why: a network trained on the scripted driver's own episodes copies the driver's gap timing only in
part (77 % action agreement on merge), and its remaining crashes come from states the driver never
visits, e.g. on the main road's fast lane at 13 m/s, already drifting towards a slower lane whose
next car is 10 m ahead. Imitation teaches nothing there (no demo row looks like it). Here each
episode's first ``k`` steps (``k`` drawn uniformly from ``roll_in_steps``) are the network's greedy
actions; from step ``k`` on a fresh scripted driver drives to the episode's end, and the shard holds
that tail: the state the network reached, then the driver's recovery from it. Every recorded action
is the driver's, so the rows are ordinary demonstrations to the replay server and the learner
(``replay.demo_paths`` takes this shard beside the ordinary one).

An episode the network ends (a crash, or the step limit) before step ``k`` records nothing; the
metadata counts them (``roll_in_ended``) beside each recorded episode's ``roll_in_steps``.

Measured (docs/RESULTS.md, "behind a safety shield"): worse than without it on merge's validation
episodes, so it stayed a probe. Run by path::

    python rollin_shard.py CHECKPOINT OUT_DIR EPISODES SEED [MAX_ROLL_IN_STEPS]

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from laneshift.demos.envsupport import make_env, resolve_env_id
from laneshift.progress import progress as progress_bar
from laneshift.tools.demos.drivers import drive_to_end, scripted_driver
from laneshift.tools.demos.writer import check_out_dir, write_shard


def generate_rollin_shard(
    out_dir: str | os.PathLike,
    *,
    checkpoint: str | os.PathLike,
    env_id_or_scenario: str,
    env_kwargs: dict,
    episodes: int,
    seed: int,
    roll_in_steps: tuple[int, int] = (0, 150),
    progress: str | None = None,
) -> Path:
    """Drive ``episodes`` episodes (reset seeds ``seed + i``): ``checkpoint``'s greedy network for
    the first ``k ~ U{roll_in_steps}`` steps, the scripted driver after; write the driver's parts
    as a shard at ``out_dir``. The env must be the one the network was trained on."""
    from laneshift.actors.evaluation import load_checkpoint_policy

    lo, hi = roll_in_steps
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, not {episodes}")
    if not 0 <= lo <= hi:
        raise ValueError(f"roll_in_steps must be 0 <= low <= high, not {roll_in_steps}")
    check_out_dir(out_dir)  # fail before driving, not after
    network = load_checkpoint_policy(checkpoint)
    env_id = resolve_env_id(env_id_or_scenario)
    env = make_env(env_id, env_kwargs)
    try:
        if tuple(env.observation_space.shape) != network.obs_shape:
            raise ValueError(f"the network takes observations of shape {network.obs_shape}, the env gives "
                             f"{tuple(env.observation_space.shape)}: pass the env settings it was trained with")
        drive = network.greedy()
        rng = np.random.default_rng(seed)
        started = time.perf_counter()
        recorded, seeds, steps_in, ended = [], [], [], 0
        for i in progress_bar(range(episodes), desc=progress or "", unit="episode", disable=progress is None):
            k = int(rng.integers(lo, hi + 1))
            obs, info = env.reset(seed=seed + i)
            done = False
            for _ in range(k):
                obs, _, terminated, truncated, info = env.step(drive(obs))
                if terminated or truncated:
                    done = True
                    break
            if done:
                ended += 1
                continue
            recorded.append(drive_to_end(env, scripted_driver(env), obs, info))  # a fresh driver: no plan yet
            seeds.append(seed + i)
            steps_in.append(k)
        if not recorded:
            raise ValueError(f"the network ended all {episodes} episodes within its roll-in: nothing to record")
        return write_shard(
            out_dir, recorded, env_id=env_id, env_kwargs=env_kwargs, recorded_by="scripted", seeds=seeds, env=env,
            extra_metadata={
                "driver": "scripted",
                "demonstrator": "laneshift.actors.envs.demonstrator.ScriptedDriver",
                "base_seed": seed,
                "roll_in": {"checkpoint": str(checkpoint), "checkpoint_sha256": _sha256(checkpoint),
                            "steps_range": [lo, hi], "steps": steps_in, "ended_in_roll_in": ended},
                "generation_seconds": round(time.perf_counter() - started, 3),
            },
        )
    finally:
        env.close()


def _sha256(path: str | os.PathLike) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


if __name__ == "__main__":
    import sys

    from laneshift.demos.shard import read_metadata

    ckpt, out, n, first = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    longest = int(sys.argv[5]) if len(sys.argv) > 5 else 150
    kwargs = {"observation": "vector", "reward_preset": 5, "initial_lane": "random", "action_set": "paper",
              "max_steps": 300, "alongside_features": True}  # the merge protocol's demo shard's env
    meta = read_metadata(generate_rollin_shard(out, checkpoint=ckpt, env_id_or_scenario="merge", env_kwargs=kwargs,
                                               episodes=n, seed=first, roll_in_steps=(0, longest)))
    print({k: meta.get(k) for k in ("episodes", "steps", "survival_rate", "achievement_rate")},
          "ended in the roll-in:", meta["roll_in"]["ended_in_roll_in"])
