"""Greedy episodes of a policy on the run's env: survival and achievement rates with 95 % Wilson
intervals (paper, Table 2), and the crashes by kind and starting lane. The loop every evaluation
runs: the learner's periodic greedy evaluation (handed to it by the builder), the launcher's final
summary, ``laneshift eval``, the studies and the baselines; and a saved checkpoint as the actors
run it (``load_checkpoint_policy``, ``evaluate_checkpoint``), and what its metadata says about the
env it was trained on (``checkpoint_env_settings``). A ``Recorder`` handed to the loop sees the
first episodes drawn by the env's ``render()`` (``laneshift eval --video``).

Survival: the episode ends without a collision or leaving the road. Achievement: the agent is
in the target lane at the last step (so a crash is never an achievement).

Room: actors (the env-running component). May import: the contract (``laneshift.config``,
``laneshift.progress``), this package's envs, gymnasium, numpy.

    >>> wilson_ci95(0, 10)[0], round(wilson_ci95(5, 10)[1], 3)
    (0.0, 0.763)
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping, NamedTuple, Protocol

import gymnasium as gym
import numpy as np

from laneshift.config import EnvConfig
from laneshift.envspec import ALLROADS, RECORDED_ENV_OPTIONS, SCENARIOS
from laneshift.progress import progress as progress_bar

from .envs import make as make_env

if TYPE_CHECKING:  # pragma: no cover
    from .policy import QPolicy


def wilson_ci95(successes: int, n: int) -> tuple[float, float]:
    if n == 0:
        return (0.0, 1.0)
    z = 1.959963984540054
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # Exact ends: round-off would otherwise leave 0/n with a lower bound of 5e-17.
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return (lo, hi)


Policy = Callable[[np.ndarray], int]
#: The paper's two initial-lane settings of the test episodes.
INITIAL_LANES = ("random", "non-target")


class Recorder(Protocol):
    """What :func:`evaluate_policy` shows the first ``episodes`` episodes it plays (the env is made
    with ``render_mode="rgb_array"`` then, so ``env.render()`` draws the top-down view)."""

    episodes: int

    def frame(self, episode: int, step: int, env: gym.Env, last: bool) -> None:
        """After the reset (step 0) and after every step (``last``: the episode's final one)."""

    def episode_end(self, episode: int, seed: int, steps: int, outcome: dict) -> None:
        """The episode is over: its reset seed, length and ``outcome`` (start_lane, survived,
        on_target_lane, return)."""


def evaluate_policy(make_policy: Callable[[gym.Env], Policy], env_cfg: EnvConfig, episodes: int,
                    seed: int = 0, progress: str | None = None, recorder: Recorder | None = None,
                    outcomes: list[dict] | None = None) -> dict:
    """``make_policy(env)`` returns the policy (obs -> action) to evaluate on that env; scripted
    drivers read the env's state, a network ignores it: ``lambda env: greedy``.

    ``progress``: the label of a progress bar on stderr (:mod:`laneshift.progress`); None: quiet.
    ``recorder``: shown the first ``recorder.episodes`` of these very episodes (same seeds, same
    actions: drawing reads the state, changes nothing); None: no env draws anything it need not.
    ``outcomes``: each episode's outcome is appended to it (:func:`episode_outcome`), so that two
    policies can be compared episode by episode on the same seeds."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, not {episodes}")
    env = make_env(env_cfg) if recorder is None else make_env(env_cfg, render_mode="rgb_array")
    policy = make_policy(env)
    if isinstance(policy, GreedyPolicy) and env_cfg.policy_vehicles:
        # The paper's third kind of vehicle: traffic driven by a copy of the model under test.
        env.unwrapped.set_npc_policy(policy.batch)
    returns, lengths, survived, achieved, shielded, npc_crashes = [], [], 0, 0, 0, 0
    # How the lane-change episodes that crashed ended: "collision" or "offroad", by starting lane.
    crashes: dict[str, dict[str, int]] = {}
    try:
        for ep in progress_bar(range(episodes), desc=progress or "", unit="episode", leave=False,
                               disable=progress is None):
            obs, info = env.reset(seed=seed + ep)
            start_lane = info.get("lane_index")
            lane, lane_changes = start_lane, []  # the steps after which the car was in another lane
            total, steps, done, shielded_before = 0.0, 0, False, shielded
            recording = recorder is not None and ep < recorder.episodes
            if recording:
                recorder.frame(ep, 0, env, False)  # type: ignore[union-attr]
            while not done:
                obs, reward, terminated, truncated, info = env.step(int(policy(obs)))
                total += float(reward)
                steps += 1
                shielded += bool(info.get("shielded", False))
                done = terminated or truncated
                if outcomes is not None and info.get("lane_index") != lane:
                    lane = info.get("lane_index")
                    lane_changes.append(steps)
                if recording:
                    recorder.frame(ep, steps, env, done)  # type: ignore[union-attr]
            crashed = bool(info.get("crashed", terminated))  # LKA: terminated = left the lane
            survived += not crashed
            achieved += (not crashed) and bool(info.get("on_target_lane", False))
            npc_crashes += int(info.get("policy_vehicle_crashes", 0))
            if recording:
                recorder.episode_end(ep, seed + ep, steps, {  # type: ignore[union-attr]
                    "start_lane": start_lane, "survived": not crashed,
                    "on_target_lane": bool(info.get("on_target_lane", False)), "return": total})
            if outcomes is not None:
                outcomes.append(episode_outcome(seed + ep, start_lane, steps, total, crashed, info,
                                                shielded - shielded_before, lane_changes))
            if crashed and start_lane is not None:
                kind = crashes.setdefault("offroad" if info.get("offroad") else "collision", {})
                kind[f"start lane {start_lane}"] = kind.get(f"start lane {start_lane}", 0) + 1
            returns.append(total)
            lengths.append(steps)
    finally:
        env.close()
    result = {"episodes": episodes, "return_mean": float(np.mean(returns)), "return_std": float(np.std(returns)),
              "length_mean": float(np.mean(lengths)), "survival_rate": survived / episodes,
              "survival_ci95": wilson_ci95(survived, episodes)}
    if not env_cfg.is_lka:
        result.update(achievement_rate=achieved / episodes, achievement_ci95=wilson_ci95(achieved, episodes),
                      crashes=crashes)
    if env_cfg.shield:  # how often the safety shield replaced the policy's action
        result["shielded_step_rate"] = shielded / max(1, sum(lengths))
    if env_cfg.policy_vehicles:  # how safely the copies of the policy drove the traffic
        result["policy_vehicle_crashes_per_episode"] = npc_crashes / episodes
    return result


def episode_outcome(seed: int, start_lane: int | None, steps: int, total: float, crashed: bool, info: dict,
                    shielded_steps: int, lane_changes: list[int] | None = None) -> dict:
    """One greedy episode, as ``laneshift eval --episodes-out`` writes it: its reset seed, the lane
    it started and ended in, its length and return, whether it survived and achieved the change,
    how it crashed (``collision`` / ``offroad``; None), the steps the shield replaced and the steps
    after which it was in another lane than before (``lane_changes``: when a change came, so that a
    late one tells from none)."""
    end_lane = info.get("lane_index")
    return {"seed": seed, "start_lane": start_lane, "end_lane": None if end_lane is None else int(end_lane),
            "steps": steps, "return": round(total, 4), "survived": not crashed,
            "achieved": (not crashed) and bool(info.get("on_target_lane", False)),
            "crash": ("offroad" if info.get("offroad") else "collision") if crashed else None,
            "shielded_steps": shielded_steps, "lane_changes": list(lane_changes or [])}


def evaluate_lanes(make_policy: Callable[[gym.Env], Policy], env_cfg: EnvConfig, episodes: int, seed: int,
                   lanes: tuple[str, ...] = INITIAL_LANES, progress: str | None = None) -> dict[str, dict]:
    """:func:`evaluate_policy` from each initial-lane setting, on the same episode seeds."""
    return {lane: evaluate_policy(make_policy, dataclasses.replace(env_cfg, initial_lane=lane), episodes, seed,
                                  progress=None if progress is None else f"{progress}, {lane} lane")
            for lane in lanes}


class GreedyPolicy:
    """A network's greedy policy: ``policy(obs) -> action`` for the ego vehicle, and ``batch`` (rows
    of observations -> actions) for the policy vehicles of ``env.policy_vehicles``, which
    :func:`evaluate_policy` drives with the same network (scripted drivers leave them as they are)."""

    def __init__(self, batch: Callable[[np.ndarray], np.ndarray]):
        self.batch = batch

    def __call__(self, obs: np.ndarray) -> int:
        return int(self.batch(np.asarray(obs)[None])[0])


class CheckpointPolicy(NamedTuple):
    """A saved network as the actors run it, with what its metadata says about it."""

    policy: "QPolicy"
    obs_shape: tuple[int, ...]
    n_actions: int
    meta: dict[str, str]

    def greedy(self) -> GreedyPolicy:
        return GreedyPolicy(self.policy.greedy)


def load_checkpoint_policy(checkpoint: str | Path) -> CheckpointPolicy:
    """Read a learner checkpoint once: its network (plain or dueling) and its metadata."""
    from .policy import QPolicy
    from laneshift.wire import safetensors_loads

    tensors, meta = safetensors_loads(Path(checkpoint).read_bytes())
    try:
        obs_shape = tuple(int(x) for x in meta["obs_shape"].split(","))
        hidden = tuple(int(x) for x in meta["hidden"].split(",") if x)
        n_actions = int(meta["n_actions"])
    except (KeyError, ValueError):
        raise ValueError(f"checkpoint {checkpoint}: missing laneshift metadata (obs_shape, hidden, n_actions)") from None
    policy = QPolicy(obs_shape, n_actions, hidden, dueling=meta.get("dueling", "0") == "1",
                     cnn=meta.get("cnn", "nature"),  # checkpoints from before the choice: Nature
                     heads=int(meta.get("heads", "1")))
    policy.load_tensors(tensors)
    return CheckpointPolicy(policy, obs_shape, n_actions, meta)


def load_greedy_policy(checkpoint: str | Path) -> GreedyPolicy:
    return load_checkpoint_policy(checkpoint).greedy()


def checkpoint_env_settings(meta: Mapping[str, str]) -> dict[str, str | bool | float]:
    """The env a checkpoint was trained on, as far as its metadata tells, as EnvConfig fields:
    ``observation`` (stacked frames, a 3-d uint8 ``obs_shape``: grayscale; a 1-d one: vector) and
    ``scenario`` (its ``env_id``, when it is one of the scenarios), and the options an evaluation
    must repeat (``RECORDED_ENV_OPTIONS``: the layout's, the shield) that the run set. Whatever it does
    not tell is left out (a checkpoint written before the learner recorded the layout options: the
    error names the option that fits).

    >>> checkpoint_env_settings({"obs_shape": "4,100,100", "obs_dtype": "|u1",
    ...                          "env_id": "laneshift/MergeLaneChange-v0"})
    {'observation': 'grayscale', 'scenario': 'merge'}
    >>> checkpoint_env_settings({"obs_shape": "82"})
    {'observation': 'vector'}
    >>> checkpoint_env_settings({"obs_shape": "88", "alongside_features": "1"})
    {'observation': 'vector', 'alongside_features': True}
    >>> checkpoint_env_settings({"obs_shape": "88", "shield": "1", "shield_gap": "2.0"})
    {'observation': 'vector', 'shield': True, 'shield_gap': 2.0}
    >>> checkpoint_env_settings({"obs_shape": "4,100,100", "frame_supersample": "4"})
    {'observation': 'grayscale', 'frame_supersample': 4}
    >>> checkpoint_env_settings({"obs_shape": "4,100,100", "frame_interval": "3"})
    {'observation': 'grayscale', 'frame_interval': 3}
    >>> checkpoint_env_settings({"obs_shape": "4,100,100", "frame_centering": "0.3"})
    {'observation': 'grayscale', 'frame_centering': 0.3}
    >>> checkpoint_env_settings({"obs_shape": "4,100,100", "frame_scale": "1"})
    {'observation': 'grayscale', 'frame_scale': 1.0}
    """
    out: dict[str, str | bool | float] = {}
    dims = [d for d in str(meta.get("obs_shape", "")).split(",") if d.strip()]
    if len(dims) == 3 or meta.get("obs_dtype") == "|u1":
        out["observation"] = "grayscale"
    elif len(dims) == 1:
        out["observation"] = "vector"
    scenario = {env_id: name for name, env_id in SCENARIOS.items()}.get(str(meta.get("env_id", "")))
    if scenario is not None:
        out["scenario"] = scenario
    defaults = EnvConfig()
    for option in RECORDED_ENV_OPTIONS:  # written by the learner where the run set them
        raw = str(meta.get(option, ""))
        if isinstance(getattr(defaults, option), bool):  # "0" / "1"
            if raw in ("0", "1"):
                out[option] = raw == "1"
        elif raw:  # a count (the frames' supersampling) or a figure (the shield's)
            try:
                out[option] = int(raw) if isinstance(getattr(defaults, option), int) else float(raw)
            except ValueError:
                pass  # not this version's writing: the env's default stands, as for an older checkpoint
    return out


def _shape_hint(trained: tuple[int, ...], given: tuple[int, ...]) -> str:
    if trained == (67,):
        return " (the 67-float vector layout is env.lane_features=false)"
    if len(trained) == len(given) == 1 and trained[0] - given[0] == 6:
        return " (6 floats more: a network trained with env.alongside_features=true; --set env.alongside_features=true)"
    if len(trained) == len(given) == 1 and given[0] - trained[0] == 6:
        return " (6 floats fewer: a network trained without env.alongside_features; drop that setting)"
    if len(trained) == len(given) == 1 and trained[0] == given[0] + len(ALLROADS):  # as many as the gap features
        return (" (an allroads network: --scenario allroads, with --set env.road=ROAD for one road; or one trained "
                "with env.gap_features=true: --set env.gap_features=true)")
    if len(trained) == len(given) == 1 and given[0] - trained[0] == 4:
        return " (4 floats fewer: a network trained without env.gap_features; drop that setting)"
    if len(trained) != len(given):  # frames against a vector, or the other way round
        kind = "grayscale" if len(trained) == 3 else "vector"
        return (f" (a {kind} checkpoint: env.observation={kind}, which `laneshift eval` takes from the checkpoint "
                f"when no --observation, --set or --config file sets it)")
    return ""


def evaluate_checkpoint(checkpoint: str | Path, env_cfg: EnvConfig, episodes: int, seed: int = 0,
                        progress: str | None = None, recorder: Recorder | None = None,
                        outcomes: list[dict] | None = None) -> dict:
    """:func:`evaluate_policy` of a checkpoint's greedy policy; ValueError (saying what fits) when
    it was trained on observations of another shape than ``env_cfg``'s env gives."""
    from .envs import spec_of

    ckpt = load_checkpoint_policy(checkpoint)
    expected = tuple(spec_of(env_cfg).schema.obs_shape)
    if ckpt.obs_shape != expected:
        raise ValueError(f"checkpoint {checkpoint} was trained on observations of shape {ckpt.obs_shape}, "
                         f"the env gives {expected}{_shape_hint(ckpt.obs_shape, expected)}")
    greedy = ckpt.greedy()
    return evaluate_policy(lambda env: greedy, env_cfg, episodes, seed, progress=progress, recorder=recorder,
                           outcomes=outcomes)


def format_result(r: dict) -> str:
    text = (f"{r['episodes']} episodes: return {r['return_mean']:.2f} +- {r['return_std']:.2f}, "
            f"length {r['length_mean']:.1f}, survival {r['survival_rate']:.0%}")
    if "achievement_rate" in r:
        text += f", achievement {r['achievement_rate']:.0%}"
    if "shielded_step_rate" in r:
        text += f", the shield replaced {r['shielded_step_rate']:.1%} of the actions"
    if "policy_vehicle_crashes_per_episode" in r:
        text += f", {r['policy_vehicle_crashes_per_episode']:.2f} policy-vehicle crashes an episode"
    agree = r.get("demo_agreement")
    if agree:
        text += (f"\n  demonstrator's action on {agree['agreement']:.0%} of {agree['states']:,} demo states"
                 + (f" (speed part {agree['speed_agreement']:.0%}, curvature part {agree['curvature_agreement']:.0%})"
                    if "speed_agreement" in agree else ""))
    for kind, by_lane in sorted(r.get("crashes", {}).items()):
        text += f"\n  {kind}: {sum(by_lane.values())} ({', '.join(f'{k}: {v}' for k, v in sorted(by_lane.items()))})"
    video = r.get("video")
    if video:
        for ep in video["episodes"]:
            ending = ("crashed" if not ep["survived"] else
                      "reached the target lane" if ep["on_target_lane"] else "survived off the target lane")
            start = "" if ep.get("start_lane") is None else f" from lane {ep['start_lane']}"
            text += f"\n  video episode {ep['episode']} (seed {ep['seed']}): {ep['steps']} steps{start}, {ending}"
        text += (f"\nvideo: {video['path']} ({video['frames']} frames at {video['fps']:g} fps, "
                 f"{video['bytes'] / 1e6:.2f} MB)")
    resp = r.get("lka_response")
    if resp:
        fmt = lambda v: "never" if v is None else f"{v:.1f} s"  # noqa: E731
        settled = resp["steering_settled_after_s"]
        steer = "steering never settled" if settled is None else f"steering settled after {settled:.1f} s"
        text += (f"\nLKA response from e1 = {resp['e1_0']} m, e2 = {resp['e2_0']} rad: |e1| <= 5 cm after "
                 f"{fmt(resp['centred_after_s'])}, {steer}"
                 f" (chatter {resp['steering_chatter_deg']:.0f} deg peak to peak over the last 5 s; MATLAB: about "
                 f"2.5 s and 2 s)")
    return text
