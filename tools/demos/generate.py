"""Generate a demo shard by letting a scripted demonstrator drive the env.

``policy="scripted"`` uses laneshift's experts from ``laneshift.actors.envs.demonstrator``
(``ScriptedDriver`` for the lane-change scenarios, ``LKAExpert`` for LKA);
``policy="human-like"`` the same experts with a reaction delay and action noise
(:mod:`.humanlike`, a stand-in for a person, labelled as such in the shard); any other callable
with the same shape works: ``policy(env)`` returns a driver and ``driver(obs)`` an
action index. A fresh driver is made for every episode, so drivers need no reset method.
Episode ``i`` is reset with seed ``seed + i`` (and the action space seeded with ``seed``), so
the same arguments give the same shard, checksum included.

The drivers and the episode loop are in ``drivers`` (shared with ``humanlike``).

Imports: laneshift.progress and the demos package (``drivers``, which imports laneshift's
demonstrators lazily; ``humanlike``, ``envsupport``, ``outcomes``, ``writer``).

Example::

    >>> path = generate_shard("runs/demos/straight", env_id_or_scenario="straight",
    ...     env_kwargs={"observation": "vector"}, episodes=50, seed=0)     # doctest: +SKIP
    >>> load_shard(path).metadata["survival_rate"]                          # doctest: +SKIP

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import inspect
import os
import time
from pathlib import Path

from laneshift.progress import progress as progress_bar
from .drivers import Driver, PolicyFactory, run_episode, scripted_driver
from laneshift.demos.envsupport import make_env, resolve_env_id
from laneshift.demos.outcomes import episode_outcome
from .humanlike import DEFAULT_ACTION_NOISE, DEFAULT_REACTION_STEPS, HumanLikePolicy
from .writer import check_out_dir, write_shard

POLICIES = ("scripted", "human-like")
#: ``achieved_only``: how many episodes may be driven per episode kept before the shard is refused.
MAX_DRIVEN_PER_KEPT = 10


def _achieved(episode: dict) -> bool:
    """Did the episode end alive on the target lane? (ValueError: its env does not say.)"""
    outcome = episode_outcome(episode["infos"][-1])
    if outcome["on_target_lane"] is None or outcome["crashed"] is None:
        raise ValueError("achieved_only: this env's info does not report 'crashed' and 'on_target_lane' "
                         "(only the lane-change scenarios do)")
    return outcome["on_target_lane"] and not outcome["crashed"]


def _driver_name(policy: PolicyFactory, driver: Driver) -> str:
    """The driver's class (e.g. ``...ScriptedDriver``), or the policy's name for plain functions."""
    named = policy if inspect.isfunction(driver) or inspect.ismethod(driver) else type(driver)
    return f"{getattr(named, '__module__', '?')}.{getattr(named, '__qualname__', repr(named))}"


def generate_shard(
    out_dir: str | os.PathLike,
    *,
    env_id_or_scenario: str,
    env_kwargs: dict,
    episodes: int,
    seed: int,
    policy: str | PolicyFactory = "scripted",
    progress: str | None = None,
    reaction_steps: int | None = None,
    action_noise: float | None = None,
    achieved_only: bool = False,
) -> Path:
    """Run ``episodes`` demonstrator episodes and write them as a shard at ``out_dir``.

    ``progress``: the label of a progress bar over the episodes on stderr; None: quiet.
    ``reaction_steps`` / ``action_noise``: the human-like stand-in's delay and noise (only with
    ``policy="human-like"``; default the calibrated :data:`~.humanlike.DEFAULT_REACTION_STEPS`,
    :data:`~.humanlike.DEFAULT_ACTION_NOISE`).
    ``achieved_only``: keep only episodes that end alive on the target lane, driving further seeds
    (``seed + episodes``, ...) until ``episodes`` are kept, at most ``MAX_DRIVEN_PER_KEPT`` times as
    many in all (ValueError beyond, and for an env whose info does not say where the episode ended).
    The shard's ``seeds`` are the kept episodes'; its metadata adds ``achieved_only``,
    ``discarded_episodes`` and ``driven_achievement_rate`` (the rate over every episode driven).

    The shard's metadata records the demonstrator's ``survival_rate`` (share of episodes
    without a crash) and ``achievement_rate`` (share ending on the target lane), each None
    when the env's info does not report it, plus ``demonstrator``, ``driver`` and
    ``base_seed``; a human-like shard has ``recorded_by`` = its stand-in label and its
    ``reaction_steps`` / ``action_noise``.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, not {episodes}")
    if policy != "human-like" and (reaction_steps is not None or action_noise is not None):
        raise ValueError("reaction_steps / action_noise are parameters of policy 'human-like'")
    check_out_dir(out_dir)  # fail before driving, not after
    recorded_by, driver_kind, extra = "scripted", "scripted", {}
    human_like: HumanLikePolicy | None = None
    if isinstance(policy, str):
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES} or a callable, not {policy!r}")
        if policy == "human-like":
            human_like = HumanLikePolicy(
                seed, DEFAULT_REACTION_STEPS if reaction_steps is None else reaction_steps,
                DEFAULT_ACTION_NOISE if action_noise is None else action_noise)
            recorded_by, driver_kind, policy = human_like.label, "human-like", human_like
        else:
            policy = scripted_driver
    else:
        driver_kind = "custom"
    env_id = resolve_env_id(env_id_or_scenario)
    env = make_env(env_id, env_kwargs)
    try:
        env.action_space.seed(seed)
        started = time.perf_counter()
        recorded, seeds, names, discarded = [], [], set(), 0
        with progress_bar(total=episodes, desc=progress or "", unit="episode", disable=progress is None) as bar:
            for i in range(episodes * (MAX_DRIVEN_PER_KEPT if achieved_only else 1)):
                driver = policy(env)  # fresh per episode: no state leaks between episodes
                # The stand-in wraps the expert: name the expert that it degrades.
                names.add(_driver_name(policy, getattr(driver, "inner", driver) if human_like else driver))
                episode = run_episode(env, driver, seed + i)
                if achieved_only and not _achieved(episode):
                    discarded += 1
                    continue
                recorded.append(episode)
                seeds.append(seed + i)
                bar.update(1)
                if len(recorded) == episodes:
                    break
        if len(recorded) < episodes:
            raise ValueError(f"achieved_only: {len(recorded)} of {len(recorded) + discarded} episodes driven ended "
                             f"on the target lane, fewer than the {episodes} asked")
        seconds = time.perf_counter() - started
        if human_like is not None:
            extra = human_like.metadata(env)
        if achieved_only:
            extra = {**extra, "achieved_only": True, "discarded_episodes": discarded,
                     "driven_achievement_rate": round(episodes / (episodes + discarded), 6)}
        return write_shard(
            out_dir,
            recorded,
            env_id=env_id,
            env_kwargs=env_kwargs,
            recorded_by=recorded_by,
            seeds=seeds,
            env=env,
            extra_metadata={
                "driver": driver_kind,
                "demonstrator": ", ".join(sorted(names)),
                "base_seed": seed,
                "generation_seconds": round(seconds, 3),
                **extra,
            },
        )
    finally:
        env.close()
