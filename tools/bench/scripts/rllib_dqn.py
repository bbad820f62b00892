"""RLlib's DQN on laneshift's straight-road lane-change env: the peer that laneshift is compared with.

What it is: a standalone benchmark (``laneshift bench all`` sets its figures beside laneshift's as
``vs_rllib_*``). It registers ``laneshift/StraightLaneChange-v0``
(vector observation, 82 floats, 9 actions) with RLlib 2.60 and trains RLlib's own DQN with the
settings of a default ``laneshift train --local`` run as far as RLlib can express them: MLP
82-256-256-9 with ReLU, batch 256, replay ratio R sampled rows per inserted transition, 2 env
runners, Double DQN, no dueling, no n-step, uniform replay of 100k, lr 5e-4, gamma 0.99, Huber
loss, global-norm clip 10, hard target sync every 500 updates, learning from 1,000 transitions,
epsilon 1.0 -> 0.1 linearly over half the env steps. It prints ONE JSON object on stdout
(progress goes to stderr): env steps, wall time, env steps/s, gradient updates and updates/s,
the peak RSS and PSS of its whole process tree (itself, Ray's gcs/raylet and every Ray worker,
sampled from /proc every 0.5 s), the versions, and the config as RLlib holds it.
docs/rllib-peer.md says what is matched and what is not.

What it may import: the standard library, ray/RLlib, torch, gymnasium, and of laneshift ONLY its
env code (``laneshift.actors.envs``: gymnasium + highway-env + pygame-ce, no zenoh, no replay
server, no learner) and ``laneshift.tools.bench.run``'s process-tree sampler (no zenoh or torch at
import), so both systems' memory is measured by the same code. RLlib 2.60 pins gymnasium 1.2.2 while laneshift pins 1.4.0, so it runs in
its own venv, ``.venv-rllib`` (laneshift installed there with ``--no-deps -e .``).

How to run it (``make bench-rllib`` creates .venv-rllib if missing and runs this):

    make bench-rllib                                    # 20,000 env steps, ratio 32
    make bench-rllib RLLIB_ARGS="--env-steps 100000 --eval-every 20000 --eval-episodes 20"   # a learning curve
    make bench-rllib RLLIB_ARGS="--env-steps 3000 --ratio 8"
    .venv-rllib/bin/python tools/bench/scripts/rllib_dqn.py --env-steps 20000 --ratio 128

Room: benchmarks (a peer, run in its own venv). May import: Ray RLlib, gymnasium, torch, laneshift's env
and memory meter (as the text above says), the standard library.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
import sys
import tempfile
import time

SCENARIO = "straight"
ENV_NAME = "laneshift-straight-vector"
# laneshift's EnvConfig defaults (src/laneshift/config/sections.py), written out: the env's constructor kwargs.
ENV_KWARGS = {"observation": "vector", "reward_preset": 5, "initial_lane": "random", "action_set": "paper"}
BATCH = 256
TARGET_SYNC_UPDATES = 500  # laneshift LearnerConfig.target_update_period (in updates)


def make_laneshift_env(env_config: dict | None = None):
    """RLlib's env creator; runs inside each env-runner process."""
    from laneshift.actors.envs import make_env  # env code only: gymnasium + highway-env

    return make_env(SCENARIO, **{**ENV_KWARGS, **(env_config or {})})


# ---------------------------------------------------------------- memory of the process tree

def _tree_sampler(root: int):
    """``laneshift bench run``'s sampler, its processes named for an RLlib run."""
    import functools

    from laneshift.tools.bench.run import TreeSampler, process_label

    return TreeSampler(root, label=functools.partial(process_label, root_label="driver (algorithm + local learner)",
                                                     actors=(("SingleAgentEnvRunner", "env-runner"),)))


# ---------------------------------------------------------------- the RLlib config

def build_config(args: argparse.Namespace):
    from ray.rllib.algorithms.dqn import DQNConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    runners, frag = args.env_runners, args.fragment
    steps_per_round = runners * frag  # env steps inserted per sampling round (all runners)
    # updates per sampling round that give R sampled rows per inserted transition
    updates_per_round = args.ratio * steps_per_round / BATCH
    if updates_per_round >= 1:
        if updates_per_round != int(updates_per_round):
            raise SystemExit(f"--ratio {args.ratio}: {steps_per_round} env steps per round x ratio / batch {BATCH} "
                             "must be a whole number of updates; change --fragment")
    elif (1 / updates_per_round) != int(1 / updates_per_round):
        raise SystemExit(f"--ratio {args.ratio}: rounds per update must be whole; change --fragment")
    # RLlib's calculate_rr_weights() divides by (num_env_runners + 1) although with remote runners the
    # local one does not sample: training_intensity R * N/(N+1) yields exactly R rows per env step.
    training_intensity = args.ratio * runners / (runners + 1)
    # laneshift syncs the target every 500 updates; RLlib counts target_network_update_freq in env steps.
    target_freq = round(TARGET_SYNC_UPDATES * BATCH / args.ratio)

    config = (
        DQNConfig()
        .api_stack(enable_rl_module_and_learner=True, enable_env_runner_and_connector_v2=True)
        .framework("torch")
        .environment(ENV_NAME, env_config={}, disable_env_checking=True)
        .env_runners(num_env_runners=runners, num_envs_per_env_runner=1, rollout_fragment_length=frag,
                     num_cpus_per_env_runner=1, explore=True)
        .learners(num_learners=0, num_gpus_per_learner=0)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=[256, 256], fcnet_activation="relu",
                                                   head_fcnet_hiddens=[]))
        .training(
            train_batch_size_per_learner=BATCH,
            lr=5e-4,
            gamma=0.99,
            double_q=True,
            dueling=False,
            n_step=1,
            num_atoms=1,
            noisy=False,
            td_error_loss_fn="huber",  # delta 1.0, as laneshift's huber_delta
            grad_clip=10.0,
            grad_clip_by="global_norm",
            adam_epsilon=1e-8,
            tau=1.0,  # hard target sync
            target_network_update_freq=target_freq,
            num_steps_sampled_before_learning_starts=1000,  # laneshift replay.min_size
            training_intensity=training_intensity,
            epsilon=[(0, 1.0), (max(1, args.env_steps // 2), 0.1)],
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 100_000},
        )
        .reporting(min_sample_timesteps_per_iteration=args.iteration_steps, min_time_s_per_iteration=None,
                   metrics_num_episodes_for_smoothing=20)
        .evaluation(evaluation_interval=None)
        .debugging(seed=args.seed, log_level="ERROR")
    )
    return config, {"training_intensity": training_intensity, "target_network_update_freq_env_steps": target_freq,
                    "env_steps_per_round": steps_per_round, "planned_updates_per_round": updates_per_round}


def config_readback(algo) -> dict:
    """The settings that matter, read back from the built algorithm's config (not our arguments)."""
    from ray.rllib.algorithms.dqn.dqn import calculate_rr_weights

    c = algo.config
    mc = c.model_config
    keys = ["num_env_runners", "num_envs_per_env_runner", "num_learners", "train_batch_size_per_learner",
            "lr", "gamma", "double_q", "dueling", "n_step", "num_atoms", "noisy", "td_error_loss_fn", "grad_clip",
            "grad_clip_by", "adam_epsilon", "tau", "target_network_update_freq",
            "num_steps_sampled_before_learning_starts", "training_intensity", "epsilon", "replay_buffer_config",
            "min_sample_timesteps_per_iteration", "seed", "enable_rl_module_and_learner",
            "enable_env_runner_and_connector_v2", "num_epochs", "minibatch_size"]
    out = {k: getattr(c, k, None) for k in keys}
    out["rollout_fragment_length"] = c.get_rollout_fragment_length()
    out["model_config"] = {k: mc.get(k) for k in ("fcnet_hiddens", "fcnet_activation", "head_fcnet_hiddens",
                                                  "head_fcnet_activation", "fcnet_use_layernorm")}
    store, train = calculate_rr_weights(c)
    out["rr_weights"] = {"sample_rounds": store, "update_rounds": train}
    out["env"] = {"name": ENV_NAME, "scenario": SCENARIO, "kwargs": ENV_KWARGS}
    return json.loads(json.dumps(out, default=str))


def q_net_layers(algo) -> tuple[list[int], int]:
    """The online Q-net's Linear layer sizes and parameter count (target nets excluded)."""
    import torch

    module = algo.learner_group._learner.module["default_policy"]
    linears = [m for name, m in module.named_modules() if isinstance(m, torch.nn.Linear) and "target" not in name]
    sizes = [linears[0].in_features] + [m.out_features for m in linears] if linears else []
    params = sum(p.numel() for m in linears for p in m.parameters())
    return sizes, params


def greedy_rates(algo, episodes: int, seed: int) -> dict:
    """The learner's Q-network, greedy, on laneshift's evaluation episodes from both initial-lane
    settings (``laneshift.actors.evaluation``, the code every laneshift evaluation uses)."""
    import torch

    from laneshift.actors.evaluation import evaluate_lanes
    from laneshift.config import EnvConfig

    module = algo.learner_group._learner.module["default_policy"]

    def greedy(obs) -> int:
        with torch.no_grad():
            batch = {"obs": torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)}
            return int(module.forward_inference(batch)["actions"][0])

    rates = evaluate_lanes(lambda _env: greedy, EnvConfig(scenario=SCENARIO, **ENV_KWARGS), episodes, seed)
    return {lane: {k: r[k] for k in ("survival_rate", "achievement_rate") if k in r} for lane, r in rates.items()}


def _dig(d: dict, *path, default=None):
    for k in path:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--env-steps", type=int, default=20_000, help="stop once this many env steps are sampled")
    ap.add_argument("--ratio", type=float, default=32, help="replay ratio: sampled rows per inserted transition")
    ap.add_argument("--env-runners", type=int, default=2, help="RLlib env runners (laneshift: --workers)")
    ap.add_argument("--fragment", type=int, default=32,
                    help="env steps per runner per sampling round (laneshift: actor.send_every)")
    ap.add_argument("--iteration-steps", type=int, default=1000,
                    help="RLlib min_sample_timesteps_per_iteration (results are reduced once per iteration)")
    ap.add_argument("--torch-threads", type=int, default=1, help="torch threads of the learner (laneshift: 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-every", type=int, default=0,
                    help="greedy evaluation of the learner's network every this many env steps (0 = none); "
                         "its time is left out of the training clock")
    ap.add_argument("--eval-episodes", type=int, default=20, help="episodes per initial lane of each evaluation")
    ap.add_argument("--eval-seed", type=int, default=200_000,
                    help="first episode seed of the evaluations (laneshift's validation episodes)")
    args = ap.parse_args(argv)

    logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    t0 = time.monotonic()
    sampler = _tree_sampler(os.getpid())
    sampler.start()

    # A private, loopback-only cluster, started as laneshift's launcher starts its own (deploy/launch.py);
    # set before Ray reads its settings.
    os.environ.pop("RAY_ADDRESS", None)
    os.environ["RAY_AUTH_MODE"] = "disabled"
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    import gymnasium
    import ray
    import torch
    from ray.tune.registry import register_env

    torch.set_num_threads(args.torch_threads)
    config, derived = build_config(args)  # refuses a ratio it cannot run before any process starts
    temp_dir = tempfile.mkdtemp(prefix="lsrl-")
    ray.init(_temp_dir=temp_dir, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False,
             num_cpus=max(os.cpu_count() or 1, args.env_runners + 1), logging_level=logging.ERROR)
    ok = False
    try:
        register_env(ENV_NAME, make_laneshift_env)
        algo = config.build_algo()
        layers, params = q_net_layers(algo)
        from ray.rllib.algorithms.dqn.dqn import calculate_rr_weights

        store, train = calculate_rr_weights(algo.config)
        planned = derived["planned_updates_per_round"]
        if train / store != planned:  # RLlib would not run the ratio asked for
            raise SystemExit(f"RLlib's round-robin weights {store}:{train} do not give {planned} updates per round")

        # Count gradient steps exactly: one learner_group.update() call is one step (num_epochs 1,
        # minibatch = the whole 256-row batch, one local learner).
        updates = [0]
        real_update = algo.learner_group.update

        def counting_update(*a, **kw):
            updates[0] += 1
            return real_update(*a, **kw)

        algo.learner_group.update = counting_update

        setup_s = time.monotonic() - t0
        print(f"rllib_dqn: set up in {setup_s:.1f} s; Q-net {layers}, {params} params; "
              f"training {args.env_steps} env steps at ratio {args.ratio:g}", file=sys.stderr)
        env_steps, result, iters = 0, {}, 0
        curve: list[dict] = []
        eval_s = 0.0  # evaluation time, left out of every training clock below
        start = time.monotonic()
        while env_steps < args.env_steps:
            result = algo.train()
            iters += 1
            env_steps = int(_dig(result, "env_runners", "num_env_steps_sampled_lifetime", default=0))
            train_s = time.monotonic() - start - eval_s
            print(f"rllib_dqn: iter {iters} env steps {env_steps} updates {updates[0]} "
                  f"{env_steps / train_s:.0f} steps/s "
                  f"return {_dig(result, 'env_runners', 'episode_return_mean')}", file=sys.stderr)
            if args.eval_every and env_steps >= (len(curve) + 1) * args.eval_every:
                e0 = time.monotonic()
                curve.append({"env_steps": env_steps, "train_s": round(train_s, 1), "updates": updates[0],
                              **greedy_rates(algo, args.eval_episodes, args.eval_seed)})
                eval_s += time.monotonic() - e0
                print(f"rllib_dqn: evaluation at {env_steps} env steps: {json.dumps(curve[-1])}", file=sys.stderr)
        wall = time.monotonic() - start - eval_s
        readback = config_readback(algo)
        rows_trained = _dig(result, "learners", "default_policy", "num_module_steps_trained_lifetime")
        algo.stop()
        ok = True
    finally:
        sampler.sample()
        ray.shutdown()
        sampler.stop()
        if ok:
            shutil.rmtree(temp_dir, ignore_errors=True)
        else:
            print(f"rllib_dqn: failed; Ray's logs are kept in {temp_dir}", file=sys.stderr)

    out = {
        "system": "rllib-dqn",
        "env_steps": env_steps,
        "wall_s": round(wall, 2),  # the training loop only (first algo.train() to the last)
        "env_steps_per_s": round(env_steps / wall, 1),
        "updates": updates[0],
        "updates_per_s": round(updates[0] / wall, 1),
        "rows_trained_reported": rows_trained,
        # sampled rows per env step: over the whole run, and over the steps after learning starts (1,000)
        "ratio_overall": round(updates[0] * BATCH / max(1, env_steps), 2),
        "ratio_after_start": round(updates[0] * BATCH / (env_steps - 1000), 2) if env_steps > 1000 else None,
        "setup_s": round(setup_s, 2),  # ray.init + building the algorithm (env runners, learner, buffer)
        "total_s": round(time.monotonic() - t0, 2),
        "iterations": iters,
        "episode_return_mean": _dig(result, "env_runners", "episode_return_mean"),
        "peak_tree_rss_mb": round(sampler.peak_rss_kb / 1024),
        "peak_tree_pss_mb": round(sampler.peak_pss_kb / 1024),
        "max_processes": sampler.max_processes,
        "processes": sampler.by_label(),
        "q_net_layers": layers,
        "q_net_params": params,
        "versions": {"ray": ray.__version__, "rllib": ray.__version__, "torch": torch.__version__,
                     "gymnasium": gymnasium.__version__, "python": sys.version.split()[0]},
        "curve": curve,  # greedy evaluations (--eval-every): survival and achievement per initial lane
        "args": vars(args),
        "derived": derived,
        "config": readback,
    }
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
