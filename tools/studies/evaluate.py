"""``laneshift eval``'s studies of a checkpoint beyond the rates: how often it agrees with the
demonstrator (``demo_agreement``) and the LKA step response against MATLAB's (``lka_response``,
``plot_lka_response``). The rates themselves (survival, achievement, 95 % Wilson intervals) come
from ``laneshift.actors.evaluation``, re-exported here for the studies.

Room: studies. May import: the contract, the components (``laneshift.actors``), matplotlib.

    >>> r = evaluate_checkpoint("runs/x/checkpoints/final.safetensors", EnvConfig(), episodes=20)  # doctest: +SKIP
    >>> r["survival_rate"], r["survival_ci95"]  # doctest: +SKIP
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import gymnasium as gym
import numpy as np

from laneshift.actors.envs import make as make_env
from laneshift.actors.evaluation import (INITIAL_LANES, CheckpointPolicy, Policy, evaluate_checkpoint,  # noqa: F401
                                         evaluate_lanes, evaluate_policy, format_result, load_checkpoint_policy,
                                         load_greedy_policy, wilson_ci95)
from laneshift.config import EnvConfig


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


