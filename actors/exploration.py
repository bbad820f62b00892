"""Exploration: epsilon as a function of a worker's env steps, and how an exploratory action is taken.

- ``linear``: the paper's linearly decaying epsilon-greedy (Table 1: 1.0 -> 0.3 or 0.1);
- ``exponential``: MATLAB's ``EpsilonDecay`` (eps <- eps * (1 - rate) each step, floored);
- ``apex``: Ape-X (Horgan et al. 2018): worker i of N keeps eps_i = e ** (1 + alpha * i / (N - 1)).

:class:`HeldExploration` (``actor.hold_mu`` > 0) is temporally-extended epsilon-greedy (ez-greedy,
Dabney, Ostrovski and Barreto 2021): with probability epsilon a random action is drawn *and a duration*
n from a zeta distribution, and the action is held for n steps. A lane change takes tens of steps of
one steering action; one-step random actions start one and the greedy policy steers back.

    >>> from laneshift.config import ActorConfig
    >>> s = make_schedule(ActorConfig(epsilon_decay_steps=100), worker_index=0)
    >>> s(0), round(s(50), 2), s(1000)
    (1.0, 0.55, 0.1)

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from laneshift.config import ActorConfig

Schedule = Callable[[int], float]


def make_schedule(cfg: ActorConfig, worker_index: int, budget: int = 0) -> Schedule:
    """``budget``: the worker's env-step budget, used when ``epsilon_decay_steps`` is 0 (auto)."""
    if cfg.exploration == "linear":
        decay_steps = cfg.epsilon_decay_steps or max(1, budget // 2)

        def linear(step: int) -> float:
            frac = min(step / decay_steps, 1.0)
            return cfg.epsilon_start + frac * (cfg.epsilon_final - cfg.epsilon_start)
        return linear
    if cfg.exploration == "exponential":
        def exponential(step: int) -> float:
            return max(cfg.epsilon_final, cfg.epsilon_start * (1.0 - cfg.epsilon_decay_rate) ** step)
        return exponential
    n = cfg.workers
    eps = cfg.apex_epsilon ** (1 + cfg.apex_alpha * worker_index / (n - 1)) if n > 1 else cfg.apex_epsilon
    return lambda step: eps


class HeldExploration:
    """ez-greedy over ``n_envs`` env copies: each copy holds its exploratory action for a drawn number
    of steps (zeta(``mu``) cut at ``hold_max``), taking the greedy action otherwise.

    >>> h = HeldExploration(n_envs=1, n_actions=9, mu=2.0, hold_max=100, rng=np.random.default_rng(2))
    >>> [int(h.act(np.array([4]), epsilon=0.5)[0]) for _ in range(5)]  # greedy 4; 0 held for 3 steps
    [0, 0, 0, 4, 2]
    """

    def __init__(self, n_envs: int, n_actions: int, mu: float, hold_max: int, rng: np.random.Generator) -> None:
        if not mu > 1.0 or hold_max < 1:
            raise ValueError(f"HeldExploration: mu must be > 1 and hold_max >= 1, got {mu!r}, {hold_max!r}")
        self.n_actions, self.rng = n_actions, rng
        weights = np.arange(1, hold_max + 1, dtype=np.float64) ** -mu
        self.durations = weights / weights.sum()  # P(n), n = 1 .. hold_max
        self.left = np.zeros(n_envs, np.int64)  # steps the held action still has, this one included
        self.held = np.zeros(n_envs, np.int64)

    def act(self, greedy: np.ndarray, epsilon: float) -> np.ndarray:
        """The actions for one step of every env copy, given their greedy actions."""
        actions = np.array(greedy, dtype=np.int64, copy=True)
        free = self.left == 0
        start = free & (self.rng.random(len(actions)) < epsilon)
        k = int(start.sum())
        if k:
            self.held[start] = self.rng.integers(0, self.n_actions, size=k)
            self.left[start] = self.rng.choice(len(self.durations), size=k, p=self.durations) + 1
        holding = self.left > 0
        actions[holding] = self.held[holding]
        self.left[holding] -= 1
        return actions

    def end_episode(self, env: int) -> None:
        """Env copy ``env`` starts a new episode: what it held ends with the old one."""
        self.left[env] = 0
