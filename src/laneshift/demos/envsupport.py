"""Resolve and build the environments demonstrations are recorded in.

The demos package never hard-codes an environment: it takes a gymnasium id (or one of
laneshift's scenario short names) plus flat env kwargs. laneshift's own ids are registered by
importing ``laneshift.actors.envs``; any other registered gymnasium id works as well.

Contract floor (the shard format resolves env ids with it). Room: the contract (shared by every process). May import: gymnasium,
``laneshift.envspec``; ``make_env`` alone imports ``laneshift.actors.envs`` (by name, at call time:
building an env is a tool's job, never the shard reader's).

Example::

    >>> resolve_env_id("CartPole-v1")
    'CartPole-v1'
    >>> env = make_env("CartPole-v1", {})
    >>> env.action_space.n
    np.int64(2)
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym

from laneshift.envspec import SCENARIOS


ENVS_MODULE = "laneshift.actors.envs"  # importing it registers laneshift's gymnasium ids


def _laneshift_envs() -> Any | None:
    """The ``laneshift.actors.envs`` module (registers the laneshift ids), or None if absent."""
    try:
        return importlib.import_module(ENVS_MODULE)
    except ImportError:
        return None


def scenarios() -> dict[str, str]:
    """laneshift's scenario short names -> gymnasium ids."""
    return dict(SCENARIOS)


def resolve_env_id(env_id_or_scenario: str) -> str:
    """Map a scenario short name (``straight``) to its gymnasium id; pass registered ids through
    (``module:Id`` imports ``module`` first). Anything else is a ValueError naming the choices."""
    known = scenarios()
    if env_id_or_scenario in known:
        return known[env_id_or_scenario]
    if env_id_or_scenario in known.values():
        return env_id_or_scenario
    try:
        gym.spec(env_id_or_scenario)
    except gym.error.Error:
        names = ", ".join(known)
        raise ValueError(f"unknown scenario or env id {env_id_or_scenario!r} (scenarios: {names}; "
                         f"or a registered gymnasium id such as CartPole-v1)") from None
    except ImportError as exc:  # module:Id whose module does not import
        raise ValueError(f"env id {env_id_or_scenario!r}: {exc}") from None
    return env_id_or_scenario


def make_env(env_id: str, env_kwargs: dict[str, Any], **extra: Any) -> gym.Env:
    """Build ``env_id`` with ``env_kwargs`` (plus ``extra`` such as ``render_mode``).

    laneshift ids go through ``laneshift.actors.envs.make_env`` so the env is built exactly as
    the actors build it; other ids through ``gymnasium.make``.
    """
    module = _laneshift_envs()
    kwargs = {**env_kwargs, **extra}
    try:
        if module is not None and env_id in scenarios().values() and hasattr(module, "make_env"):
            return module.make_env(env_id, **kwargs)
        return gym.make(env_id, **kwargs)
    except TypeError as exc:  # an env kwarg the env does not take: the caller's input, said as such
        if "unexpected keyword argument" not in str(exc):
            raise
        raise ValueError(f"{env_id}: {exc}".split(" was raised from")[0]) from None


def gymnasium_make_id(env_id: str) -> str:
    """The id ``gymnasium.make`` takes in a fresh process: laneshift's ids need the module that
    registers them (``laneshift.actors.envs:laneshift/StraightLaneChange-v0``); others as given.

    Example::

        >>> gymnasium_make_id("CartPole-v1")
        'CartPole-v1'
    """
    if ":" not in env_id and env_id in scenarios().values():
        return f"{ENVS_MODULE}:{env_id}"
    return env_id
