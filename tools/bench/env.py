"""`laneshift bench env`: environment speed against highway-fast-v0, and baseline policies.

Speed: the straight lane-change scenario (vector observation) and highway-env's highway-fast-v0
(its default Kinematics observation), each driven by uniformly random actions for ``--steps``
steps in this one process, resets included.  Both steps/s and simulated seconds per wall-clock
second are reported, since one laneshift step simulates 1/policy_frequency = 0.1 s while one
highway-fast-v0 step simulates 1 s.

Baselines (``--baselines``): the straight scenario's 300-step evaluation (``--scenario`` picks
another), for both initial-lane settings, with a random policy, a keep-lane constant-speed policy
and the ScriptedDriver: survival rate (no collision / off-road in 300 steps) and achievement rate
(on the target lane at step 300), as in the paper's Table 2; plus the LKAExpert on the LKA plant.

Room: the tools (benchmarks). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import gymnasium as gym
import numpy as np

from laneshift.tools.argtypes import non_negative_int, positive_int
from laneshift.progress import progress


def register(subparsers: Any) -> None:
    """Add the ``env`` sub-command (``laneshift.tools.cli`` calls this under ``laneshift bench``)."""
    p = subparsers.add_parser("env", help="env speed vs highway-fast-v0, and baseline policies")
    _add_arguments(p)
    p.set_defaults(func=run)


def _add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--steps", type=positive_int, default=600, help="random-action steps per env (default 600)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the envs and the random actions")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--baselines", action="store_true", help="also evaluate random / keep-lane / scripted policies")
    p.add_argument("--episodes", type=positive_int, default=100, help="episodes per baseline row (default 100)")
    p.add_argument(
        "--scenario",
        default="straight",
        choices=("straight", "merge", "curve", "roundabout"),
        help="scenario of the --baselines table (default straight, the paper's evaluation task)",
    )


def measure(env: gym.Env, steps: int, seed: int, bar: Any = None) -> dict[str, float]:
    """Random-action throughput of ``env`` over ``steps`` steps, resets included. ``bar``: a
    progress bar moved every 100 steps (negligible next to a step)."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    episodes = 0
    t0 = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            episodes += 1
            env.reset()
        if bar is not None and i % 100 == 99:
            bar.update(100)
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.update(steps % 100)
    return {"steps_per_s": steps / wall, "episodes": episodes, "wall_s": wall}


def speed(steps: int, seed: int, bar: Any = None) -> dict[str, float]:
    """Side-by-side speed of laneshift's straight scenario and highway-fast-v0."""
    import highway_env  # noqa: F401  (registers highway-fast-v0)

    from laneshift.actors import envs as ls_envs

    ours = gym.make(ls_envs.SCENARIOS["straight"])
    ours_dt = 1.0 / ours.unwrapped.policy_frequency
    ours_gray = gym.make(ls_envs.SCENARIOS["straight"], observation="grayscale")
    hw = gym.make("highway-fast-v0")
    hw_dt = 1.0 / hw.unwrapped.config["policy_frequency"]
    # Warm-up outside the timed loops (imports, first renders).
    for e in (ours, ours_gray, hw):
        e.reset(seed=seed)
        e.step(e.action_space.sample())
    a = measure(ours, steps, seed, bar)
    g = measure(ours_gray, steps, seed, bar)
    b = measure(hw, steps, seed, bar)
    for e in (ours, ours_gray, hw):
        e.close()
    return {
        "laneshift_steps_per_s": a["steps_per_s"],
        "highway_fast_steps_per_s": b["steps_per_s"],
        "ratio": a["steps_per_s"] / b["steps_per_s"],
        "laneshift_sim_s_per_wall_s": a["steps_per_s"] * ours_dt,
        "highway_fast_sim_s_per_wall_s": b["steps_per_s"] * hw_dt,
        "sim_time_ratio": (a["steps_per_s"] * ours_dt) / (b["steps_per_s"] * hw_dt),
        "laneshift_step_sim_s": ours_dt,
        "highway_fast_step_sim_s": hw_dt,
        "laneshift_grayscale_steps_per_s": g["steps_per_s"],
        "steps": steps,
    }


def evaluate(
    policy: str, initial_lane: str, episodes: int, seed: int, max_steps: int = 300, scenario: str = "straight",
    bar: Any = None,
) -> dict[str, Any]:
    """Survival / achievement of one baseline policy on ``scenario`` over ``max_steps``-step episodes."""
    from laneshift.actors import envs as ls_envs
    from laneshift.actors.envs.demonstrator import KeepLaneDriver, ScriptedDriver

    env = gym.make(ls_envs.SCENARIOS[scenario], initial_lane=initial_lane, max_steps=max_steps)
    rng = np.random.default_rng(seed)
    survived = achieved = 0
    returns, lengths = [], []
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed * 100_003 + ep)
        driver = {"random": None, "keep-lane": KeepLaneDriver, "scripted": ScriptedDriver}[policy]
        driver = driver(env) if driver else None
        total = 0.0
        while True:
            action = int(rng.integers(env.action_space.n)) if driver is None else driver(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            if terminated or truncated:
                break
        ok = not info["crashed"]
        survived += ok
        achieved += ok and info["on_target_lane"]
        returns.append(total)
        lengths.append(info["steps"])
        if bar is not None:
            bar.update()
    env.close()
    return {
        "policy": policy,
        "initial_lane": initial_lane,
        "episodes": episodes,
        "survival": survived / episodes,
        "achievement": achieved / episodes,
        "mean_return": float(np.mean(returns)),
        "mean_steps": float(np.mean(lengths)),
    }


def baselines(episodes: int, seed: int, scenario: str = "straight", bar: Any = None) -> list[dict[str, Any]]:
    return [
        evaluate(policy, lane, episodes, seed, scenario=scenario, bar=bar)
        for lane in ("random", "non-target")
        for policy in ("random", "keep-lane", "scripted")
    ]


def lka_expert(episodes: int, seed: int, bar: Any = None) -> dict[str, Any]:
    """LKAExpert on LaneKeepingAssist-v0: survival (|e1| <= 1 m for 150 steps) and returns, over
    random resets and from MATLAB's demo start (e1 = -0.4 m, e2 = 0.2 rad)."""
    from laneshift.actors import envs as ls_envs
    from laneshift.actors.envs.demonstrator import LKAExpert

    env = gym.make(ls_envs.SCENARIOS["lka"])
    expert = LKAExpert(env)

    def episode(**reset: Any) -> tuple[float, bool, list[float]]:
        obs, _ = env.reset(**reset)
        total, e1 = 0.0, []
        while True:
            obs, reward, terminated, truncated, _ = env.step(expert(obs))
            total += reward
            e1.append(float(obs[0]))
            if terminated or truncated:
                if bar is not None:
                    bar.update()
                return total, not terminated, e1

    runs = [episode(seed=seed * 100_003 + ep) for ep in range(episodes)]
    demo_return, _, demo_e1 = episode(seed=seed, options={"e1": -0.4, "e2": 0.2})
    settle = next(i for i in range(len(demo_e1)) if all(abs(v) < 0.05 for v in demo_e1[i:]))
    return {
        "episodes": episodes,
        "survival": sum(ok for _, ok, _ in runs) / episodes,
        "mean_return": float(np.mean([r for r, _, _ in runs])),
        "demo_return": demo_return,
        "demo_settle_s": (settle + 1) * env.unwrapped.params.Ts,
    }


def run(args: argparse.Namespace) -> int:
    if args.steps < 1 or args.episodes < 1:
        raise SystemExit("--steps and --episodes must be >= 1")
    with progress(total=3 * args.steps, desc="bench env speed", unit="step") as bar:
        result: dict[str, Any] = speed(args.steps, args.seed, bar)
    if args.baselines:
        result["baselines_scenario"] = args.scenario
        # 6 rows of episodes, then the LKA expert's random resets and its one demo episode.
        with progress(total=7 * args.episodes + 1, desc="bench env baselines", unit="episode") as bar:
            result["baselines"] = baselines(args.episodes, args.seed, args.scenario, bar)
            result["lka_expert"] = lka_expert(args.episodes, args.seed, bar)
    if args.json:
        print(json.dumps(result))
        return 0
    r = result
    print(f"env speed, random actions, {r['steps']} steps each, resets included (one process)")
    print(f"  {'env':38s} {'steps/s':>9s} {'sim s/step':>10s} {'sim s / wall s':>15s}")
    print(f"  {'laneshift StraightLaneChange (vector)':38s} {r['laneshift_steps_per_s']:9.0f} {r['laneshift_step_sim_s']:10.2f} {r['laneshift_sim_s_per_wall_s']:15.0f}")
    print(f"  {'laneshift StraightLaneChange (grayscale)':38s} {r['laneshift_grayscale_steps_per_s']:9.0f} {r['laneshift_step_sim_s']:10.2f} {r['laneshift_grayscale_steps_per_s'] * r['laneshift_step_sim_s']:15.0f}")
    print(f"  {'highway-fast-v0 (Kinematics)':38s} {r['highway_fast_steps_per_s']:9.1f} {r['highway_fast_step_sim_s']:10.2f} {r['highway_fast_sim_s_per_wall_s']:15.1f}")
    print(f"  ratio (steps/s): {r['ratio']:.1f}x   ratio (simulated time/s): {r['sim_time_ratio']:.1f}x")
    if args.baselines:
        print(f"\nbaselines: {args.scenario} scenario, 300-step episodes, {args.episodes} episodes per row")
        print(f"  {'initial lane':12s} {'policy':10s} {'survival':>9s} {'achievement':>12s} {'mean return':>12s} {'mean steps':>11s}")
        for b in r["baselines"]:
            print(
                f"  {b['initial_lane']:12s} {b['policy']:10s} {100 * b['survival']:8.0f}% "
                f"{100 * b['achievement']:11.0f}% {b['mean_return']:12.1f} {b['mean_steps']:11.1f}"
            )
        k = r["lka_expert"]
        print(
            f"\nLKAExpert on LaneKeepingAssist-v0, {k['episodes']} random resets: survival {100 * k['survival']:.0f}%, "
            f"mean return {k['mean_return']:.2f}; from e1=-0.4 m, e2=0.2 rad: return {k['demo_return']:.2f}, "
            f"|e1| < 5 cm for good after {k['demo_settle_s']:.1f} s"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="laneshift bench env", description=__doc__.splitlines()[0])
    _add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
