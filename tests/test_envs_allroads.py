"""Scenario allroads (the four roads, one network): the road drawn from the reset seed, a pinned
road, the road's one-hot in the observation, the single-road episodes reproduced, max_steps, the
grayscale refusal, the scripted driver and the human-like stand-in driving it, its config, spec and
default demo shard.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from laneshift.actors.envs import make, make_env, spec_of
from laneshift.actors.envs.demonstrator import KeepLaneDriver, ScriptedDriver
from laneshift.config import ConfigError, EnvConfig
from laneshift.envspec import ALLROADS


def test_the_road_is_drawn_from_the_reset_seed_and_covers_all_four():
    env, again = make_env("allroads", max_steps=5), make_env("allroads", max_steps=5)
    roads = [env.reset(seed=s)[1]["road"] for s in range(12)]
    assert roads == [ALLROADS[s % 4] for s in range(12)] and set(roads) == set(ALLROADS)
    for s in (0, 7, 100_002, 200_019):  # the same road and the same episode whichever env, whatever came before
        a, b = env.reset(seed=s), again.reset(seed=s)
        assert a[1]["road"] == b[1]["road"] == ALLROADS[s % 4] and np.array_equal(a[0], b[0])
    # Unseeded resets draw from the env's generator: reproducible after a seeded reset, all four roads.
    runs = []
    for e in (env, again):
        e.reset(seed=3)
        runs.append([(info["road"], obs.tobytes()) for obs, info in (e.reset() for _ in range(24))])
    assert runs[0] == runs[1] and {road for road, _ in runs[0]} == set(ALLROADS)


def test_a_pinned_road_and_a_one_episode_road():
    env = make_env("allroads", road="merge", max_steps=5)
    assert {env.reset(seed=s)[1]["road"] for s in range(6)} == {"merge"}
    assert {env.reset()[1]["road"] for _ in range(6)} == {"merge"}
    free = make_env("allroads", max_steps=5)
    assert free.reset(seed=0, options={"road": "roundabout"})[1]["road"] == "roundabout"
    assert free.reset(seed=0)[1]["road"] == "straight"  # the option held for one episode
    # A pinned road leaves the episode of a seed as it is: seed 1 is merge's episode 1 either way.
    assert np.array_equal(env.reset(seed=1)[0], free.reset(seed=1)[0])
    with pytest.raises(ValueError, match="road must be one of straight, merge, curve, roundabout"):
        make_env("allroads", road="highway")
    with pytest.raises(ValueError, match=r"options\['road'\]"):
        free.reset(seed=0, options={"road": "lka"})
    # The config: env.road pins it; refused beside another scenario or a bad name, with one line.
    assert make(EnvConfig(scenario="allroads", road="curve", max_steps=5)).reset(seed=0)[1]["road"] == "curve"
    with pytest.raises(ConfigError, match="env.road: pins the road of env.scenario=allroads only"):
        EnvConfig(scenario="merge", road="merge")
    with pytest.raises(ConfigError, match="env.road: must be empty"):
        EnvConfig(scenario="allroads", road="ramp")


def test_the_observation_is_the_road_envs_with_the_roads_one_hot():
    env = make_env("allroads", max_steps=300, initial_lane="non-target")
    assert env.observation_space.shape == (86,) and env.action_space.n == 9
    for s in range(4):
        obs, info = env.reset(seed=100_000 + s)
        road = ALLROADS[s]
        assert info["road"] == road and obs.dtype == np.float32 and env.observation_space.contains(obs)
        assert obs[-4:].tolist() == [float(r == road) for r in ALLROADS]
        single = make_env(road, max_steps=300, initial_lane="non-target")
        ref, _ = single.reset(seed=100_000 + s)
        assert single.observation_space.shape == (82,) and np.array_equal(obs[:82], ref)  # same layout, same episode
        for action in (0, 3, 1, 4, 6, 2):
            obs, reward, term, trunc, info = env.step(action)
            ref, ref_reward, *_ = single.step(action)
            assert np.array_equal(obs[:82], ref) and reward == ref_reward and obs[-4:].argmax() == s
    check_env(make_env("allroads", render_mode="rgb_array", policy_vehicles=2).unwrapped)


def test_policy_vehicles_read_the_road_too():
    env = make_env("allroads", policy_vehicles=2, max_steps=5)
    seen = []
    env.unwrapped.set_npc_policy(lambda batch: seen.append(batch.copy()) or np.zeros(len(batch), int))
    for s in range(4):
        env.reset(seed=s)
        env.step(0)
        assert seen[-1].shape[1] == 86 and (seen[-1][:, -4:] == np.eye(4)[s]).all()


def test_max_steps_applies_on_every_road_and_grayscale_is_refused():
    env = make_env("allroads", max_steps=7)
    assert make_env("allroads").unwrapped.max_steps == 300  # the default: the test episodes' length
    for s in range(4):
        env.reset(seed=s)
        steps = 0
        while True:
            steps += 1
            *_, term, trunc, info = env.step(0)
            if term or trunc:
                break
        assert steps <= 7 and (term or (trunc and steps == 7 and info["steps"] == 7))
    assert make(EnvConfig(scenario="allroads", max_steps=9)).unwrapped.road_envs["roundabout"].max_steps == 9
    with pytest.raises(ValueError, match="allroads takes 'vector' only"):
        make_env("allroads", observation="grayscale")
    with pytest.raises(ConfigError, match="env.observation: allroads needs the vector observation"):
        EnvConfig(scenario="allroads", observation="grayscale")


def test_the_scripted_driver_completes_allroads_episodes_as_on_each_road():
    env = make_env("allroads", max_steps=80)
    for s in range(4):  # one episode per road: survived, and the very actions of the single-road episode
        driver, obs = ScriptedDriver(env), env.reset(seed=s)[0]
        single = make_env(ALLROADS[s], max_steps=80)
        ref_driver, ref = ScriptedDriver(single), single.reset(seed=s)[0]
        while True:
            action = driver(obs)
            assert action == ref_driver(ref)
            obs, _, term, trunc, info = env.step(action)
            ref = single.step(action)[0]
            if term or trunc:
                break
        assert trunc and not info["crashed"] and info["road"] == ALLROADS[s]
    keep = KeepLaneDriver(env)
    env.reset(seed=2)
    assert 0 <= keep() < 9


def test_the_human_like_stand_in_and_the_demo_shard_drive_it(tmp_path):
    from laneshift.tools.demos.generate import generate_shard
    from laneshift.tools.demos.humanlike import measure
    from laneshift.demos.shard import load_shard

    rates = measure("allroads", {"max_steps": 30}, 4, 0, 5, 0.07)
    assert rates["survival_rate"] is not None
    path = generate_shard(tmp_path / "shard", env_id_or_scenario="allroads", env_kwargs={"max_steps": 20},
                          episodes=4, seed=10_000)
    shard = load_shard(path)
    assert shard.observations.shape[1:] == (86,)
    assert set(np.argmax(shard.observations[:, -4:], axis=1).tolist()) == {0, 1, 2, 3}  # seeds 10,000-10,003


def test_spec_and_the_default_demo_shards_name():
    from laneshift.config import load_run_config
    from laneshift.deploy.run_dir import default_demo_dir

    spec = spec_of(EnvConfig(scenario="allroads"))
    assert spec.env_id == "laneshift/AllRoadsLaneChange-v0" and spec.schema.obs_shape == (86,)
    assert spec.schema.n_actions == 9
    cfg = load_run_config(overrides={"env.scenario": "allroads", "env.road": "merge", "train.run_dir": "runs/x"})
    assert default_demo_dir(cfg, 40).name.startswith("allroads-merge-vector86-")
    assert default_demo_dir(cfg.replace(env=EnvConfig(scenario="allroads")), 40).name.startswith("allroads-vector86-")


def test_the_default_demo_shard_of_non_target_starts_has_its_own_name():
    """A run trained from non-target lanes only gets demonstrations started there, never the
    random-lane shard that another run left in the same folder (or the other way round)."""
    from laneshift.config import load_run_config
    from laneshift.deploy.run_dir import default_demo_dir

    random_lane = load_run_config(overrides={"env.scenario": "merge", "train.run_dir": "runs/x"})
    non_target = load_run_config(overrides={"env.scenario": "merge", "env.initial_lane": "non-target",
                                            "train.run_dir": "runs/x"})
    assert "-non-target-" not in default_demo_dir(random_lane, 40).name
    assert "-non-target-scripted-v" in default_demo_dir(non_target, 40).name
    # The driver's successes only (train.demo_achieved_only) are other demonstrations too.
    achieved = random_lane.replace(train=dataclasses.replace(random_lane.train, demo_achieved_only=True))
    assert default_demo_dir(achieved, 40) != default_demo_dir(random_lane, 40)
    assert default_demo_dir(achieved, 40).name == default_demo_dir(random_lane, 40).name.replace(
        "-scripted-v", "-achieved-scripted-v")
