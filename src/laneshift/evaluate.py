"""Greedy evaluation of a checkpoint: survival and achievement rates (paper, Table 2).

Survival: the episode ends without a collision or leaving the road. Achievement: the agent is
in the target lane at the last step (so a crash is never an achievement). Rates come with 95 %
Wilson score intervals.

    >>> r = evaluate_checkpoint("runs/x/checkpoints/final.safetensors", EnvConfig(), episodes=20)  # doctest: +SKIP
    >>> r["survival_rate"], r["survival_ci95"]  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable, NamedTuple

import gymnasium as gym
import numpy as np

from .config import EnvConfig
from .envspec import make_env
from .progress import progress as progress_bar

if TYPE_CHECKING:  # pragma: no cover
    from laneshift.actors.policy import QPolicy


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


def evaluate_policy(make_policy: Callable[[gym.Env], Policy], env_cfg: EnvConfig, episodes: int,
                    seed: int = 0, progress: str | None = None) -> dict:
    """``make_policy(env)`` returns the policy (obs -> action) to evaluate on that env; scripted
    drivers read the env's state, a network ignores it: ``lambda env: greedy``.

    ``progress``: the label of a progress bar on stderr (:mod:`laneshift.progress`); None: quiet."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, not {episodes}")
    env = make_env(env_cfg)
    policy = make_policy(env)
    returns, lengths, survived, achieved = [], [], 0, 0
    # How the lane-change episodes that crashed ended: "collision" or "offroad", by starting lane.
    crashes: dict[str, dict[str, int]] = {}
    try:
        for ep in progress_bar(range(episodes), desc=progress or "", unit="episode", leave=False,
                               disable=progress is None):
            obs, info = env.reset(seed=seed + ep)
            start_lane = info.get("lane_index")
            total, steps, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, info = env.step(int(policy(obs)))
                total += float(reward)
                steps += 1
                done = terminated or truncated
            crashed = bool(info.get("crashed", terminated))  # LKA: terminated = left the lane
            survived += not crashed
            achieved += (not crashed) and bool(info.get("on_target_lane", False))
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
    return result


def evaluate_lanes(make_policy: Callable[[gym.Env], Policy], env_cfg: EnvConfig, episodes: int, seed: int,
                   lanes: tuple[str, ...] = INITIAL_LANES, progress: str | None = None) -> dict[str, dict]:
    """:func:`evaluate_policy` from each initial-lane setting, on the same episode seeds."""
    return {lane: evaluate_policy(make_policy, dataclasses.replace(env_cfg, initial_lane=lane), episodes, seed,
                                  progress=None if progress is None else f"{progress}, {lane} lane")
            for lane in lanes}


class CheckpointPolicy(NamedTuple):
    """A saved network as the actors run it, with what its metadata says about it."""

    policy: "QPolicy"
    obs_shape: tuple[int, ...]
    n_actions: int
    meta: dict[str, str]

    def greedy(self) -> Policy:
        return lambda obs: int(self.policy.greedy(np.asarray(obs)[None])[0])


def load_checkpoint_policy(checkpoint: str | Path) -> CheckpointPolicy:
    """Read a learner checkpoint once: its network (plain or dueling) and its metadata."""
    from laneshift.actors.policy import QPolicy
    from laneshift.wire import safetensors_loads

    tensors, meta = safetensors_loads(Path(checkpoint).read_bytes())
    try:
        obs_shape = tuple(int(x) for x in meta["obs_shape"].split(","))
        hidden = tuple(int(x) for x in meta["hidden"].split(",") if x)
        n_actions = int(meta["n_actions"])
    except (KeyError, ValueError):
        raise ValueError(f"checkpoint {checkpoint}: missing laneshift metadata (obs_shape, hidden, n_actions)") from None
    policy = QPolicy(obs_shape, n_actions, hidden, dueling=meta.get("dueling", "0") == "1",
                     cnn=meta.get("cnn", "nature"))  # checkpoints from before the choice: Nature
    policy.load_tensors(tensors)
    return CheckpointPolicy(policy, obs_shape, n_actions, meta)


def load_greedy_policy(checkpoint: str | Path) -> Policy:
    return load_checkpoint_policy(checkpoint).greedy()


def demo_agreement(checkpoint: str | Path, shard_path: str | Path) -> dict:
    """How often the checkpoint's greedy action is the demonstrator's on the shard's states (an
    imitation diagnostic: the action set, speed part and curvature part separately)."""
    from laneshift.demos.shard import load_shard

    ckpt = load_checkpoint_policy(checkpoint)
    shard = load_shard(shard_path)
    if tuple(shard.observations.shape[1:]) != ckpt.obs_shape:
        raise ValueError(f"the shard's observations {tuple(shard.observations.shape[1:])} do not fit the "
                         f"checkpoint's {ckpt.obs_shape}")
    chunks = np.array_split(shard.observations, max(1, len(shard.actions) // 4096))
    chosen = np.concatenate([ckpt.policy.greedy(chunk) for chunk in chunks])
    demo = np.asarray(shard.actions)
    out = {"states": int(demo.size), "agreement": float(np.mean(chosen == demo))}
    if ckpt.n_actions == 9:  # paper actions: index = 3 * speed + curvature
        out["speed_agreement"] = float(np.mean(chosen // 3 == demo // 3))
        out["curvature_agreement"] = float(np.mean(chosen % 3 == demo % 3))
    return out


def evaluate_checkpoint(checkpoint: str | Path, env_cfg: EnvConfig, episodes: int, seed: int = 0,
                        progress: str | None = None) -> dict:
    from laneshift.envspec import env_spec

    ckpt = load_checkpoint_policy(checkpoint)
    expected = tuple(env_spec(env_cfg).schema.obs_shape)
    if ckpt.obs_shape != expected:
        hint = " (the 67-float vector layout is env.lane_features=false)" if ckpt.obs_shape == (67,) else ""
        raise ValueError(f"checkpoint {checkpoint} was trained on observations of shape {ckpt.obs_shape}, "
                         f"the env gives {expected}{hint}")
    greedy = ckpt.greedy()
    return evaluate_policy(lambda env: greedy, env_cfg, episodes, seed, progress=progress)


def lka_response(make_policy: Callable[[gym.Env], Policy], e1: float = -0.4, e2: float = 0.2,
                 centre_band_m: float = 0.05, steer_band_deg: float = 1.0) -> dict:
    """The MATLAB example's response test: drive from (e1, e2) for one episode, greedily.

    ``centred_after_s``: the first time after which |e1| <= ``centre_band_m`` for the rest of the
    episode (None if never). ``steering_settled_after_s``: the first time after which the steering
    stays within ``steer_band_deg`` of its final value (the median of the last 2 s), None unless that
    holds for at least the last second. The band is one 1-degree action step: the equilibrium
    steering on this road (about 0.16 deg) lies between two actions, so the best steady state
    alternates between neighbours. The MATLAB reference: centred within about 2.5 s, steering settled after about 2 s.
    """
    env = make_env(EnvConfig(scenario="lka"))
    policy = make_policy(env)
    try:
        obs, info = env.reset(seed=0, options={"e1": e1, "e2": e2})
        dt = float(getattr(env.unwrapped, "ts", 0.1))
        times, lateral, yaw, steer = [0.0], [float(info["e1"])], [float(info["e2"])], [0.0]
        done, total, terminated = False, 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(int(policy(obs)))
            total += float(reward)
            done = terminated or truncated
            times.append(round(len(times) * dt, 6))
            lateral.append(float(info["e1"]))
            yaw.append(float(info["e2"]))
            steer.append(float(np.degrees(info["steering"])))
    finally:
        env.close()
    lat, st = np.abs(np.asarray(lateral)), np.asarray(steer)

    def settled_after(ok: np.ndarray) -> float | None:
        if not ok[-1]:
            return None
        bad = np.flatnonzero(~ok)
        return times[bad[-1] + 1] if len(bad) else 0.0

    # The steering's final value: the median of the last 2 s; "settled" must hold for the last second
    # at least, or the last sample would trivially count as settled on itself.
    final_steer = float(np.median(st[-int(round(2.0 / dt)):]))
    steer_settled = settled_after(np.abs(st - final_steer) <= steer_band_deg)
    if steer_settled is not None and steer_settled > times[-1] - 1.0:
        steer_settled = None
    return {"e1_0": e1, "e2_0": e2, "return": total, "left_lane": bool(terminated),
            "centred_after_s": settled_after(lat <= centre_band_m),
            "steering_settled_after_s": steer_settled,
            # Peak-to-peak steering over the last 5 s: a policy can centre the car while chattering.
            "steering_chatter_deg": float(np.ptp(st[-int(round(5.0 / dt)):])),
            "final_e1": lateral[-1], "final_e2": yaw[-1],
            "trace": {"t": times, "e1": lateral, "e2": yaw, "steering_deg": steer}}


def plot_lka_response(resp: dict, path: str | Path) -> Path:
    """The MATLAB figure: lateral error, yaw error and steering over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tr = resp["trace"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for ax, key, label in zip(axes, ("e1", "e2", "steering_deg"),
                              ("lateral deviation e1 [m]", "relative yaw e2 [rad]", "steering [deg]")):
        ax.plot(tr["t"], tr[key], lw=1.5)
        ax.axhline(0.0, color="grey", lw=0.6)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].axhspan(-0.05, 0.05, color="tab:green", alpha=0.15, label="|e1| <= 5 cm")
    if resp["centred_after_s"] is not None:
        axes[0].axvline(resp["centred_after_s"], color="tab:green", ls="--",
                        label=f"centred after {resp['centred_after_s']:.1f} s")
    if resp["steering_settled_after_s"] is not None:
        axes[2].axvline(resp["steering_settled_after_s"], color="tab:orange", ls="--",
                        label=f"settled after {resp['steering_settled_after_s']:.1f} s")
        axes[2].legend(loc="upper right")
    axes[0].legend(loc="lower right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"LKA response from e1 = {resp['e1_0']} m, e2 = {resp['e2_0']} rad")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def format_result(r: dict) -> str:
    text = (f"{r['episodes']} episodes: return {r['return_mean']:.2f} +- {r['return_std']:.2f}, "
            f"length {r['length_mean']:.1f}, survival {r['survival_rate']:.0%}")
    if "achievement_rate" in r:
        text += f", achievement {r['achievement_rate']:.0%}"
    agree = r.get("demo_agreement")
    if agree:
        text += (f"\n  demonstrator's action on {agree['agreement']:.0%} of {agree['states']:,} demo states"
                 + (f" (speed part {agree['speed_agreement']:.0%}, curvature part {agree['curvature_agreement']:.0%})"
                    if "speed_agreement" in agree else ""))
    for kind, by_lane in sorted(r.get("crashes", {}).items()):
        text += f"\n  {kind}: {sum(by_lane.values())} ({', '.join(f'{k}: {v}' for k, v in sorted(by_lane.items()))})"
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
