"""A "human-like" stand-in demonstrator: the scripted driver made slow and sloppy. Not a person.

The paper's demonstrations come from a person driving; its Table 2 reports that driver's
scores on the straight scenario (random initial lane, 300-step test episodes): survival
50.7 %, achievement 50.3 %. Where no recording of a person exists, this module degrades
laneshift's scripted expert (``ScriptedDriver``, ``LKAExpert`` for LKA) in the two ways a
person differs from it most visibly:

* **reaction delay** ``k`` steps: the action taken at step ``t`` is the one the scripted driver
  chose on the state of step ``max(0, t - k)`` (it is called every step, so its own plan follows
  the road; only what reaches the car is late). At the env's 10 Hz, ``k = 5`` is 0.5 s;
* **action noise** ``p``: with probability ``p`` the (delayed) action is replaced by one drawn
  uniformly from all of the env's actions (the 9 paper actions on the lane-change scenarios).

The noise generator of the episode reset with seed ``s`` is ``default_rng([NOISE_SALT, s])``,
so the same command writes the same shard (same sha256). Shards written with it are labelled
:func:`stand_in_label` in ``recorded_by``: every result that uses one says it is a stand-in.
The defaults were calibrated with :func:`calibrate` (``python -m laneshift.tools.demos.humanlike``,
table in ``docs/demos.md``) to land near the paper's human row.

Imports: numpy, gymnasium, and the demos package's ``drivers`` (laneshift's demonstrators, lazily),
``envsupport`` and ``outcomes``; never ``generate``, which imports this module.

Example::

    >>> policy = HumanLikePolicy(seed=0, reaction_steps=5, action_noise=0.07)
    >>> generate_shard("runs/demos/human-like", env_id_or_scenario="straight", env_kwargs={},
    ...                episodes=50, seed=0, policy="human-like")       # doctest: +SKIP

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from .drivers import Driver, run_episode, scripted_driver
from laneshift.demos.envsupport import make_env, resolve_env_id
from laneshift.demos.outcomes import episode_outcome, outcome_rates

# Calibrated on the straight scenario with its defaults (docs/demos.md, "calibration"): the
# setting whose survival / achievement over 200 episodes (seeds 0..199) came closest to Table
# 2's human row: 54.0 % / 48.0 % against 50.7 % / 50.3 %. Survival falls steeply between k = 3
# (>= 88 % for p <= 0.3) and k = 6 (<= 16 %): the delayed lane keeping starts to oscillate.
DEFAULT_REACTION_STEPS = 5
DEFAULT_ACTION_NOISE = 0.07
# The paper's human driver (Table 2, random initial lane): survival, achievement in %.
PAPER_HUMAN = (50.7, 50.3)
# Salt of the per-episode noise generator, so the noise stream is not the env's own seed stream.
NOISE_SALT = 0x68756D61  # "huma"
STAND_IN_PREFIX = "human-like stand-in"


def stand_in_label(reaction_steps: int, action_noise: float) -> str:
    """The ``recorded_by`` of a human-like shard: says what it is and that it is not a person."""
    return (f"{STAND_IN_PREFIX} (scripted driver + reaction delay {reaction_steps} steps + "
            f"action noise {action_noise:g}); not a person")


def check_parameters(reaction_steps: int, action_noise: float) -> None:
    """ValueError unless ``reaction_steps`` >= 0 is an int and 0 <= ``action_noise`` <= 1."""
    if isinstance(reaction_steps, bool) or not isinstance(reaction_steps, (int, np.integer)) \
            or reaction_steps < 0:
        raise ValueError(f"reaction_steps must be an integer >= 0, not {reaction_steps!r}")
    if not 0.0 <= float(action_noise) <= 1.0:
        raise ValueError(f"action_noise must be a probability in [0, 1], not {action_noise!r}")


class HumanLikeDriver:
    """Wraps a driver (``driver(obs) -> action``): delays its actions by ``reaction_steps`` and
    replaces each with a uniformly random one of ``n_actions`` with probability ``action_noise``.

    Made fresh for every episode (like ScriptedDriver): it has no reset method.
    """

    def __init__(self, inner: Driver, n_actions: int, reaction_steps: int, action_noise: float,
                 rng: np.random.Generator) -> None:
        check_parameters(reaction_steps, action_noise)
        self.inner = inner
        self.n_actions = int(n_actions)
        self.reaction_steps = int(reaction_steps)
        self.action_noise = float(action_noise)
        self.rng = rng
        # The inner driver's decisions not yet acted on: the last k + 1 of them.
        self._pending: deque[int] = deque()
        self.noisy_steps = 0  # how many actions the noise replaced (for tests and summaries)

    def __call__(self, obs: Any = None) -> int:
        # The inner driver sees every step (its plan must follow the car); the car gets the
        # decision of k steps ago, or the first one while fewer than k steps have passed.
        self._pending.append(int(self.inner(obs)))
        action = self._pending[0]
        if len(self._pending) > self.reaction_steps:
            self._pending.popleft()
        # Two draws every step, whatever the outcome, so that one step's noise never shifts the
        # random stream of the later steps (the same episode stays comparable across p).
        slip, random_action = self.rng.random(), int(self.rng.integers(self.n_actions))
        if slip < self.action_noise:
            self.noisy_steps += 1
            return random_action
        return action


class HumanLikePolicy:
    """Policy factory for :func:`laneshift.tools.demos.generate.generate_shard`: ``policy(env)`` -> a fresh
    :class:`HumanLikeDriver` around the scripted expert, one per episode.

    ``generate_shard`` makes one driver per episode, in order, and resets episode ``i`` with
    seed ``seed + i``; the factory counts the drivers it made, so the noise of the episode
    reset with seed ``s`` is always ``default_rng([NOISE_SALT, s])``.
    """

    def __init__(self, seed: int, reaction_steps: int = DEFAULT_REACTION_STEPS,
                 action_noise: float = DEFAULT_ACTION_NOISE,
                 inner: Callable[[gym.Env], Driver] | None = None) -> None:
        check_parameters(reaction_steps, action_noise)
        self.seed = int(seed)
        self.reaction_steps = int(reaction_steps)
        self.action_noise = float(action_noise)
        self.inner = inner
        self._made = 0

    @property
    def label(self) -> str:
        return stand_in_label(self.reaction_steps, self.action_noise)

    def __call__(self, env: gym.Env) -> HumanLikeDriver:
        inner = scripted_driver(env) if self.inner is None else self.inner(env)
        episode_seed = self.seed + self._made
        self._made += 1
        if not isinstance(env.action_space, gym.spaces.Discrete):
            raise ValueError(f"the human-like driver needs a Discrete action space, not {env.action_space}")
        return HumanLikeDriver(inner, int(env.action_space.n), self.reaction_steps,
                               self.action_noise, np.random.default_rng([NOISE_SALT, episode_seed]))

    def metadata(self, env: gym.Env) -> dict[str, Any]:
        """What a shard records about this stand-in (besides ``recorded_by``)."""
        hz = getattr(env.unwrapped, "policy_frequency", None)
        return {
            "driver": "human-like",
            "stand_in": True,
            "reaction_steps": self.reaction_steps,
            "reaction_delay_s": None if not hz else round(self.reaction_steps / float(hz), 6),
            "action_noise": self.action_noise,
            "noise_seeding": f"numpy default_rng([{NOISE_SALT}, episode reset seed])",
        }


def measure(env_id_or_scenario: str, env_kwargs: dict, episodes: int, seed: int,
            reaction_steps: int, action_noise: float) -> dict[str, float | None]:
    """Survival / achievement rates of the stand-in over ``episodes`` (nothing written).

    Drives exactly as ``generate_shard`` does (same seeds, same drivers), without storing.
    """
    env = make_env(resolve_env_id(env_id_or_scenario), env_kwargs)
    try:
        env.action_space.seed(seed)
        policy = HumanLikePolicy(seed, reaction_steps, action_noise)
        outcomes = []
        for i in range(episodes):
            driver = policy(env)
            outcomes.append(episode_outcome(run_episode(env, driver, seed + i)["infos"][-1]))
        return outcome_rates(outcomes)
    finally:
        env.close()


def calibrate(reaction_steps: Sequence[int], action_noise: Sequence[float], *, episodes: int = 200,
              seed: int = 0, scenario: str = "straight", env_kwargs: dict | None = None,
              out: Callable[[str], None] = print) -> list[dict[str, Any]]:
    """Measure every (k, p) of the grid and print a table sorted by distance to the paper's
    human row (|survival - 50.7| + |achievement - 50.3|, percentage points)."""
    rows = []
    out(f"{scenario} {env_kwargs or {}}: {episodes} episodes per setting, seeds {seed}..{seed + episodes - 1}")
    out(f"{'k':>3} {'p':>5} {'survival %':>11} {'achievement %':>14} {'distance':>9} {'seconds':>8}")
    for k, p in itertools.product(reaction_steps, action_noise):
        started = time.perf_counter()
        rates = measure(scenario, dict(env_kwargs or {}), episodes, seed, k, p)
        survival = 100 * (rates["survival_rate"] or 0.0)
        achievement = 100 * (rates["achievement_rate"] or 0.0)
        distance = abs(survival - PAPER_HUMAN[0]) + abs(achievement - PAPER_HUMAN[1])
        row = {"reaction_steps": k, "action_noise": p, "survival": survival,
               "achievement": achievement, "distance": distance,
               "seconds": time.perf_counter() - started}
        rows.append(row)
        out(f"{k:>3} {p:>5g} {survival:>11.1f} {achievement:>14.1f} {distance:>9.1f} {row['seconds']:>8.1f}")
    best = min(rows, key=lambda r: r["distance"])
    out(f"closest to the paper's human driver ({PAPER_HUMAN[0]} / {PAPER_HUMAN[1]} %): "
        f"k={best['reaction_steps']} p={best['action_noise']:g} "
        f"({best['survival']:.1f} / {best['achievement']:.1f} %)")
    return rows


def main(argv: list[str] | None = None) -> int:
    """``python -m laneshift.tools.demos.humanlike --reaction-steps 0 2 4 --action-noise 0 0.1``."""
    parser = argparse.ArgumentParser(
        prog="python -m laneshift.tools.demos.humanlike",
        description="Calibrate the human-like stand-in against Table 2's human driver row.")
    parser.add_argument("--reaction-steps", type=int, nargs="+", default=[DEFAULT_REACTION_STEPS])
    parser.add_argument("--action-noise", type=float, nargs="+", default=[DEFAULT_ACTION_NOISE])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenario", default="straight")
    parser.add_argument("--initial-lane", choices=("random", "non-target"), default=None,
                        help="the env's initial_lane (default: the scenario's, random)")
    args = parser.parse_args(argv)
    kwargs = {"initial_lane": args.initial_lane} if args.initial_lane else {}
    calibrate(args.reaction_steps, args.action_noise, episodes=args.episodes, seed=args.seed,
              scenario=args.scenario, env_kwargs=kwargs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
