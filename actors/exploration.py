"""Exploration schedules: epsilon as a function of a worker's env steps.

- ``linear``: the paper's linearly decaying epsilon-greedy (Table 1: 1.0 -> 0.3 or 0.1);
- ``exponential``: MATLAB's ``EpsilonDecay`` (eps <- eps * (1 - rate) each step, floored);
- ``apex``: Ape-X (Horgan et al. 2018): worker i of N keeps eps_i = e ** (1 + alpha * i / (N - 1)).

    >>> from laneshift.config import ActorConfig
    >>> s = make_schedule(ActorConfig(epsilon_decay_steps=100), worker_index=0)
    >>> s(0), round(s(50), 2), s(1000)
    (1.0, 0.55, 0.1)

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from typing import Callable

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
