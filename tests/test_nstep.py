"""n-step items: the online accumulator, the whole-shard conversion, and the learner's target.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from laneshift.config import LearnerConfig
from laneshift.learner.dqn import DoubleDQN
from laneshift.nstep import NStepAccumulator, nstep_arrays


def _reference(rewards, terminated_last, n, gamma):
    """Item t of one episode, written out from the definition."""
    T = len(rewards)
    out = []
    for t in range(T):
        k = min(n, T - t)
        ret = sum(gamma**i * rewards[t + i] for i in range(k))
        term = terminated_last and t + k == T
        out.append((ret, t + k, k, term))  # next_obs index = t + k (obs index, 0..T)
    return out


def test_accumulator_matches_the_definition_on_a_terminated_episode():
    rewards = [1.0, -2.0, 0.5, 3.0, 1.0]
    acc = NStepAccumulator(3, 0.9)
    items = []
    for t, r in enumerate(rewards):
        last = t == len(rewards) - 1
        items += acc.push(t, t % 9, r, t + 1, last, False)
    assert len(acc) == 0 and [it.obs for it in items] == [0, 1, 2, 3, 4]
    for it, (ret, nxt, k, term) in zip(items, _reference(rewards, True, 3, 0.9)):
        assert it.reward == pytest.approx(ret) and it.next_obs == nxt and it.steps == k and it.terminated == term
    assert [it.terminated for it in items] == [False, False, True, True, True]


def test_truncation_bootstraps_and_flush_keeps_unfinished_items():
    acc = NStepAccumulator(4, 0.5)
    assert acc.push("s0", 0, 1.0, "s1", False, False) == []
    out = acc.push("s1", 0, 1.0, "s2", False, True)  # time limit
    assert [(it.obs, it.next_obs, it.steps, it.terminated, it.truncated) for it in out] == [
        ("s0", "s2", 2, False, True), ("s1", "s2", 1, False, True)]
    assert out[0].reward == pytest.approx(1.5)
    acc.push("a", 1, 2.0, "b", False, False)
    flushed = acc.flush("b")
    assert [(it.obs, it.next_obs, it.steps, it.terminated) for it in flushed] == [("a", "b", 1, False)]
    assert len(acc) == 0


def test_one_step_items_are_plain_transitions():
    acc = NStepAccumulator(1, 0.99)
    (it,) = acc.push("s", 3, 2.5, "s'", False, False)
    assert (it.obs, it.action, it.reward, it.next_obs, it.steps, it.terminated) == ("s", 3, 2.5, "s'", 1, False)


@pytest.mark.parametrize("n,gamma", [(0, 0.9), (256, 0.9), (True, 0.9), (2, 1.5), (2, -0.1)])
def test_bad_parameters_are_refused(n, gamma):
    with pytest.raises(ValueError):
        NStepAccumulator(n, gamma)


@settings(max_examples=60, deadline=None)
@given(lengths=st.lists(st.integers(1, 12), min_size=1, max_size=5), n=st.integers(1, 6),
       terminal=st.lists(st.booleans(), min_size=5, max_size=5), seed=st.integers(0, 2**16))
def test_shard_conversion_equals_the_online_accumulator(lengths, n, terminal, seed):
    """The replay server's demo conversion and the actors' accumulator give the same items."""
    rng = np.random.default_rng(seed)
    gamma = 0.9
    obs_rows, rewards, next_obs, terms, ids, online = [], [], [], [], [], []
    for e, T in enumerate(lengths):
        acc = NStepAccumulator(n, gamma)
        ob = rng.normal(size=(T + 1, 2)).astype(np.float32)
        rs = rng.normal(size=T).astype(np.float32)
        for t in range(T):
            last = t == T - 1
            term = last and terminal[e]
            online += acc.push(ob[t], 0, float(rs[t]), ob[t + 1], term, last and not term)
            obs_rows.append(ob[t]); rewards.append(rs[t]); next_obs.append(ob[t + 1]); terms.append(term); ids.append(e)
    ret, nxt, term, steps = nstep_arrays(np.array(rewards, np.float32), np.array(next_obs), np.array(terms, np.uint8),
                                         np.array(ids), n, gamma)
    assert len(online) == len(rewards)
    np.testing.assert_allclose(ret, [it.reward for it in online], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(nxt, np.stack([it.next_obs for it in online]))
    assert term.tolist() == [int(it.terminated) for it in online]
    assert steps.tolist() == [it.steps for it in online]


def test_learner_discounts_the_bootstrap_by_gamma_to_the_steps():
    """Zero network output at next_obs except through the target: compare the TD target directly."""
    cfg = LearnerConfig(hidden=(8,), batch_size=3, gamma=0.5, lr=1e-9)
    agent = DoubleDQN((2,), 2, cfg)
    for p in [*agent.online.parameters(), *agent.target.parameters()]:
        torch.nn.init.zeros_(p)
    agent.target.net[-1].bias.data[:] = torch.tensor([4.0, 4.0])  # Q_target(s', .) = 4 everywhere
    batch = dict(obs=np.zeros((3, 2), np.float32), action=np.zeros(3, np.int64), reward=np.ones(3, np.float32),
                 next_obs=np.zeros((3, 2), np.float32), terminated=np.array([0, 0, 1], np.uint8),
                 steps=np.array([1, 3, 3], np.uint8), weight=np.ones(3, np.float32))
    agent.update(batch)
    # Q(s, a) = 0, so td = -(1 + 0.5^k * 4 * (1 - terminated)): 3, 1.5, 1
    np.testing.assert_allclose(agent.last_td_abs, [3.0, 1.5, 1.0], rtol=1e-5)


class _RecordingLinks:
    """The worker's seams, in memory: one weights version, every transitions batch kept."""

    def __init__(self, weights):
        self.weights = weights  # one wire.Weights, taken by the first wait
        self.batches: list = []

    def send_transitions(self, batch) -> None:
        from laneshift import wire

        # Through the wire's bytes, as the zenoh links send it.
        self.batches.append(wire.decode_transitions(wire.encode_transitions(batch), self.schema))

    def send_episode(self, record) -> None:
        pass

    def flush(self):
        from laneshift.actors.seams import Delivery

        return Delivery()

    def latest_weights(self):
        return None

    def wait_weights(self, timeout: float):
        w, self.weights = self.weights, None
        return w

    def wait_insert_ok(self) -> None:
        pass

    def stop_requested(self) -> bool:
        return False


def _worker_items(n_step: int, env_steps: int) -> tuple[dict, list[int]]:
    from laneshift.actors.worker import EnvWorker
    from laneshift.config import ActorConfig, EnvConfig
    from laneshift.actors.envs import spec_of
    from laneshift.qnet import build_q_network
    from laneshift.qnet import weights_of

    env_cfg = EnvConfig(scenario="straight", max_steps=40)  # several episode ends in the run
    spec = spec_of(env_cfg)
    torch.manual_seed(0)
    links = _RecordingLinks(weights_of(build_q_network(spec.schema.obs_shape, spec.schema.n_actions, (16,)), 0, 0, 0))
    links.schema = spec.schema
    worker = EnvWorker("w0", 0, env_cfg, ActorConfig(send_every=16, epsilon_final=0.5), (16,), sync=False,
                       rehearsal=False, n_step=n_step, gamma=0.9)
    worker.run(links, env_steps)
    worker.close()
    cols = {k: np.concatenate([getattr(b, k) for b in links.batches])
            for k in ("obs", "action", "reward", "next_obs", "terminated", "truncated", "steps")}
    return cols, [len(b) for b in links.batches]


def test_worker_sends_the_n_step_items_of_its_one_step_trajectory():
    """Same seeds, same actions: the n = 3 worker's items are the n-step conversion of what the n = 1
    worker sent, one item per env step (the budget's unfinished window included)."""
    one, _ = _worker_items(1, 150)
    three, sizes = _worker_items(3, 150)
    assert len(one["action"]) == len(three["action"]) == 150
    np.testing.assert_array_equal(one["obs"], three["obs"])
    np.testing.assert_array_equal(one["action"], three["action"])
    # Episode ids from the 1-step stream; the budget's end acts like an episode end (flush).
    ends = (one["terminated"] | one["truncated"]).astype(bool)
    ids = np.concatenate([[0], np.cumsum(ends)[:-1]])
    ret, nxt, term, steps = nstep_arrays(one["reward"], one["next_obs"], one["terminated"], ids, 3, 0.9)
    np.testing.assert_allclose(three["reward"], ret, rtol=1e-6)
    np.testing.assert_array_equal(three["next_obs"], nxt)
    np.testing.assert_array_equal(three["terminated"], term)
    np.testing.assert_array_equal(three["steps"], steps)
    assert set(steps.tolist()) == {1, 2, 3} and sizes[0] == 16 - 2  # the first window completes at step 3


def test_the_learner_hands_every_row_field_the_update_reads_to_the_agent():
    """A sampled batch split into updates keeps `steps` (a lost column would silently bootstrap
    n-step returns with gamma instead of gamma^n)."""
    from laneshift import wire
    from laneshift.learner.batches import UPDATE_FIELDS, split_updates

    n = 6
    rows = {"obs": np.zeros((n, 2), np.float32), "next_obs": np.zeros((n, 2), np.float32),
            "action": np.zeros(n, np.int64), "reward": np.zeros(n, np.float32), "terminated": np.zeros(n, np.uint8),
            "steps": np.arange(1, n + 1, dtype=np.uint8), "is_demo": np.zeros(n, np.uint8),
            "index": np.arange(n, dtype=np.int64), "weight": np.ones(n, np.float32)}
    parts = split_updates(wire.SampledBatch(num_batches=2, **rows))
    assert set(UPDATE_FIELDS) <= set(parts[0]) and "steps" in UPDATE_FIELDS
    assert parts[1]["steps"].tolist() == [4, 5, 6]
    # Sampled without next observations (SampleRequest(next_obs=False)): every other field.
    parts = split_updates(wire.SampledBatch(num_batches=2, **{**rows, "next_obs": None}))
    assert set(parts[0]) == set(UPDATE_FIELDS) - {"next_obs"} and parts[1]["steps"].tolist() == [4, 5, 6]


def test_n_step_run_in_process(tmp_path):
    """The whole graph (workers, replay core, learner) with 3-step items."""
    from laneshift.config import load_run_config
    from laneshift.deploy.inprocess import train_inprocess

    cfg = load_run_config(overrides={
        "env.scenario": "lka", "actor.send_every": 50, "learner.hidden": "32,32", "learner.batch_size": 32,
        "learner.publish_every": 5, "learner.n_step": 3, "replay.min_size": 100, "replay.samples_per_insert": 4,
        "replay.spi_tolerance": 512, "train.env_steps": 1000, "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    assert result["replay"]["tables"]["online"]["inserted"] == 1000  # one item per env step
    assert result["updates"] > 0 and result["replay"]["rejected"] == {}
