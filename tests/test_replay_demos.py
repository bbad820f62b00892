"""Demo shards in the replay server: loaded, validated against the run's env, sampled intact.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift import wire
from laneshift.actors.envs import spec_of
from laneshift.config import load_run_config
from laneshift.tools.demos.generate import generate_shard
from laneshift.demos.shard import load_shard
from laneshift.replay_server.service import build_core


@pytest.fixture(scope="module")
def straight_shard(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("demos") / "straight"
    return str(generate_shard(out, env_id_or_scenario="straight", env_kwargs={"observation": "vector"},
                              episodes=3, seed=0))


def test_sampled_demo_items_are_byte_identical_to_the_file(straight_shard):
    cfg = load_run_config(overrides={"env.scenario": "straight", "replay.demo_mode": "rehearsal",
                                     "replay.demo_paths": straight_shard})
    core = build_core(cfg, spec_of(cfg.env))
    shard = load_shard(straight_shard)
    assert core.stats()["tables"]["demo"]["sha256"] == shard.sha256
    reply = core.handle_sample_query(wire.encode_sample_request(wire.SampleRequest(256, 2)))
    batch = wire.decode_batch(reply, core.schema)
    assert batch.is_demo.all()
    rows = batch.index
    for name, ours in (("obs", shard.observations), ("next_obs", shard.next_observations),
                       ("action", shard.actions), ("reward", shard.rewards)):
        assert getattr(batch, name).tobytes() == np.ascontiguousarray(ours[rows]).astype(
            getattr(batch, name).dtype).tobytes(), name
    assert (batch.terminated == shard.terminations[rows]).all()


def test_n_step_runs_serve_the_shard_as_n_step_items(straight_shard):
    """learner.n_step > 1: the demo table holds each episode's n-step items (laneshift.nstep)."""
    from laneshift.nstep import nstep_arrays

    cfg = load_run_config(overrides={"env.scenario": "straight", "replay.demo_mode": "rehearsal",
                                     "replay.demo_paths": straight_shard, "learner.n_step": 5})
    core = build_core(cfg, spec_of(cfg.env))
    shard = load_shard(straight_shard)
    ret, nxt, term, steps = nstep_arrays(shard.rewards, shard.next_observations, shard.terminations,
                                         shard.episode_ids, 5, cfg.learner.gamma)
    batch = wire.decode_batch(core.handle_sample_query(wire.encode_sample_request(wire.SampleRequest(256, 1))),
                              core.schema)
    rows = batch.index
    np.testing.assert_array_equal(batch.obs, shard.observations[rows])
    np.testing.assert_array_equal(batch.reward, ret[rows])
    np.testing.assert_array_equal(batch.next_obs, nxt[rows])
    np.testing.assert_array_equal(batch.steps, steps[rows])
    np.testing.assert_array_equal(batch.terminated, term[rows])
    assert steps.max() == 5 and steps.min() == 1  # episode ends shorten the last windows


def test_shard_of_another_env_or_preset_is_refused(straight_shard):
    cfg = load_run_config(overrides={"env.scenario": "lka", "replay.demo_mode": "rehearsal",
                                     "replay.demo_paths": straight_shard})
    with pytest.raises(ValueError, match="replay.demo_paths: .*(env|shape)"):
        build_core(cfg, spec_of(cfg.env))
    cfg = load_run_config(overrides={"env.scenario": "straight", "env.reward_preset": 2,
                                     "replay.demo_mode": "rehearsal", "replay.demo_paths": straight_shard})
    with pytest.raises(ValueError, match="reward_preset=5.*reward_preset=2"):
        build_core(cfg, spec_of(cfg.env))


def test_retention_refuses_a_shard_too_small_for_the_ratio(straight_shard):
    cfg = load_run_config(overrides={"env.scenario": "straight", "replay.demo_mode": "retention",
                                     "replay.capacity": 1_000_000, "replay.demo_paths": straight_shard})
    with pytest.raises(ValueError, match="replay.demo_ratio: retention needs 100000 demo transitions"):
        build_core(cfg, spec_of(cfg.env))
