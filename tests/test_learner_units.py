"""Learner and actor building blocks: Double DQN updates, weights on the wire and on disk,
exploration schedules and the epsilon-greedy policy. Tiny nets, CPU, seeded, no sleeps.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from laneshift import wire
from laneshift.actors.exploration import HeldExploration, make_schedule
from laneshift.actors.policy import QPolicy
from laneshift.config import ActorConfig, ConfigError, LearnerConfig
from laneshift.learner.dqn import DoubleDQN
from laneshift.qnet import build_q_network
from laneshift.qnet import load_checkpoint, load_into, save_checkpoint, tensors_digest, to_wire

torch.set_num_threads(1)


def _cfg(**kw) -> LearnerConfig:
    return LearnerConfig(**{"hidden": (16,), "batch_size": 8, "seed": 0, **kw})


def _last_linear(net: torch.nn.Module) -> torch.nn.Linear:
    return [m for m in net.modules() if isinstance(m, torch.nn.Linear)][-1]


@torch.no_grad()
def _set_constant_q(net: torch.nn.Module, values: list[float]) -> None:
    """Make the network output ``values`` for every input (last layer: zero weights, bias = values)."""
    last = _last_linear(net)
    last.weight.zero_()
    last.bias.copy_(torch.tensor(values))


def _batch(obs, action, reward, next_obs, terminated) -> dict[str, np.ndarray]:
    return {"obs": np.asarray(obs, np.float32), "action": np.asarray(action, np.int64),
            "reward": np.asarray(reward, np.float32), "next_obs": np.asarray(next_obs, np.float32),
            "terminated": np.asarray(terminated, np.uint8), "steps": np.ones(len(action), np.uint8),
            "weight": np.ones(len(action), np.float32)}


# --------------------------------------------------------------------------- Double DQN


def test_converges_to_true_q_values_on_a_two_state_problem():
    """States A=[1,0], B=[0,1]; gamma 0.9.
    A: action 0 -> reward 1, terminal; action 1 -> reward 0, next state B.
    B: action 0 -> reward 2, terminal; action 1 -> reward -1, terminal.
    True Q: Q(B,0)=2, Q(B,1)=-1, Q(A,0)=1, Q(A,1)=0.9*max Q(B)=1.8."""
    A, B = [1, 0], [0, 1]
    batch = _batch(obs=[A, A, B, B], action=[0, 1, 0, 1], reward=[1, 0, 2, -1], next_obs=[A, B, A, A],
                   terminated=[1, 0, 1, 1])
    agent = DoubleDQN((2,), 2, _cfg(hidden=(32,), lr=1e-2, gamma=0.9, target_update_period=20, huber_delta=10.0))
    for _ in range(400):
        agent.update(batch)
    with torch.no_grad():
        q = agent.online(torch.tensor([A, B], dtype=torch.float32)).numpy()
    np.testing.assert_allclose(q, [[1.0, 1.8], [2.0, -1.0]], atol=1e-3)
    assert agent.greedy(np.array([A, B], np.float32)).tolist() == [1, 0]
    assert agent.updates == 400


def _td_target(double: bool) -> float:
    """One update on a constructed case; returns the TD target the update used."""
    agent = DoubleDQN((2,), 2, _cfg(double=double, gamma=0.5, target_update_period=1000))
    _set_constant_q(agent.online, [1.0, 0.0])  # online argmax at s' = action 0
    _set_constant_q(agent.target, [5.0, 10.0])  # target argmax at s' = action 1
    out = agent.update(_batch(obs=[[0, 0]], action=[0], reward=[0], next_obs=[[1, 1]], terminated=[0]))
    # One row: td_abs = |q - target| with q = online(s)[0] = 1 below every candidate target.
    return 1.0 + out["td_abs"]


def test_double_dqn_online_chooses_target_values():
    assert _td_target(double=True) == pytest.approx(0.5 * 5.0)  # target's value of the online argmax


def test_vanilla_dqn_takes_the_target_max():
    assert _td_target(double=False) == pytest.approx(0.5 * 10.0)


def test_terminal_transitions_do_not_bootstrap():
    agent = DoubleDQN((2,), 2, _cfg(gamma=0.99))
    _set_constant_q(agent.online, [0.0, 0.0])
    _set_constant_q(agent.target, [100.0, 100.0])
    out = agent.update(_batch(obs=[[0, 0]], action=[1], reward=[3], next_obs=[[0, 0]], terminated=[1]))
    assert out["td_abs"] == pytest.approx(3.0) and out["q_mean"] == pytest.approx(0.0)


def test_a_terminal_step_bootstraps_the_terminal_value_discounted_by_its_steps():
    agent = DoubleDQN((2,), 2, _cfg(gamma=0.5, terminal_value=-100.0))
    _set_constant_q(agent.online, [0.0, 0.0])
    _set_constant_q(agent.target, [8.0, 8.0])
    b = _batch(obs=[[0, 0]] * 3, action=[0, 0, 0], reward=[3, 3, 3], next_obs=[[0, 0]] * 3, terminated=[1, 1, 0])
    b["steps"] = np.array([1, 2, 2], np.uint8)  # n-step items: the crash 1 and 2 steps ahead, then a live row
    agent.update(b)
    # crash after 1 step: 3 + 0.5 * -100; after 2: 3 + 0.25 * -100; alive: 3 + 0.25 * 8 (Double DQN's target).
    assert agent._last.td_target.tolist() == pytest.approx([-47.0, -22.0, 5.0])
    plain = DoubleDQN((2,), 2, _cfg(gamma=0.5))
    _set_constant_q(plain.target, [8.0, 8.0])
    plain.update(b)
    assert plain._last.td_target.tolist() == pytest.approx([3.0, 3.0, 5.0])  # the paper's: nothing after a crash


def test_target_sync_period():
    agent = DoubleDQN((3,), 2, _cfg(target_update_period=5, lr=1e-2))
    rng = np.random.default_rng(0)
    b = _batch(obs=rng.normal(size=(8, 3)), action=rng.integers(0, 2, 8), reward=rng.normal(size=8),
               next_obs=rng.normal(size=(8, 3)), terminated=np.zeros(8))

    def same() -> bool:
        o, t = agent.online.state_dict(), agent.target.state_dict()
        return all(torch.equal(o[k], t[k]) for k in o)

    assert same()  # the target starts as a copy
    frozen = {k: v.clone() for k, v in agent.target.state_dict().items()}
    for i in range(1, 11):
        agent.update(b)
        if i % 5 == 0:
            assert same(), i
            frozen = {k: v.clone() for k, v in agent.target.state_dict().items()}
        else:
            assert not same(), i
            assert all(torch.equal(frozen[k], v) for k, v in agent.target.state_dict().items()), i
    assert not any(p.requires_grad for p in agent.target.parameters())


def test_gradient_clipping_bound_holds():
    agent = DoubleDQN((3,), 2, _cfg(grad_clip=0.5, huber_delta=1e6, lr=1e-6))
    b = _batch(obs=np.full((8, 3), 10.0), action=np.zeros(8), reward=np.full(8, 1e4), next_obs=np.zeros((8, 3)),
               terminated=np.ones(8))
    out = agent.update(b)
    assert out["grad_norm"] > 10.0  # before clipping, far above the bound
    total = math.sqrt(sum(float(p.grad.norm()) ** 2 for p in agent.online.parameters()))
    assert total <= 0.5 + 1e-5


def test_importance_weights_scale_the_loss():
    def loss(w: float) -> float:
        agent = DoubleDQN((2,), 2, _cfg())
        b = _batch(obs=[[0, 1]], action=[0], reward=[1], next_obs=[[0, 1]], terminated=[1])
        b["weight"] = np.array([w], np.float32)
        return agent.update(b)["loss"]

    assert loss(0.0) == 0.0 and loss(3.0) == pytest.approx(3 * loss(1.0))


def test_reset_optimizer_syncs_target_and_is_deterministic():
    a, b = DoubleDQN((4,), 3, _cfg()), DoubleDQN((4,), 3, _cfg())
    assert tensors_digest({k: v.numpy() for k, v in a.online.state_dict().items()}) == tensors_digest(
        {k: v.numpy() for k, v in b.online.state_dict().items()})  # seeded init
    with torch.no_grad():
        for p in a.online.parameters():
            p.add_(1.0)
    a.reset_optimizer()
    assert all(torch.equal(a.online.state_dict()[k], v) for k, v in a.target.state_dict().items())


def _random_batch(rng: np.random.Generator, rows: int = 8) -> dict[str, np.ndarray]:
    return _batch(rng.normal(size=(rows, 4)), rng.integers(0, 3, rows), rng.normal(size=rows),
                  rng.normal(size=(rows, 4)), rng.integers(0, 2, rows))


def test_weight_average_is_the_ema_of_the_online_weights_and_what_is_handed_out():
    decay = 0.9
    agent = DoubleDQN((4,), 3, _cfg(ema_decay=decay))
    assert agent.policy_net is agent.averaged and agent.averaged is not agent.online
    expected = {k: v.clone() for k, v in agent.online.state_dict().items()}  # the average starts at online
    rng = np.random.default_rng(0)
    for _ in range(5):
        agent.update(_random_batch(rng))
        for k, v in agent.online.state_dict().items():
            expected[k] = decay * expected[k] + (1 - decay) * v
    for k, v in agent.averaged.state_dict().items():
        assert torch.allclose(v, expected[k], atol=1e-6), k
    assert not all(torch.allclose(a, o) for a, o in zip(agent.averaged.parameters(), agent.online.parameters()))
    obs = rng.normal(size=(6, 4)).astype(np.float32)
    with torch.no_grad():
        assert np.array_equal(agent.greedy(obs), agent.averaged(torch.from_numpy(obs)).argmax(1).numpy())
    # A restarted learner goes on from the same average; a state saved without one restarts it at online.
    restored = DoubleDQN((4,), 3, _cfg(ema_decay=decay))
    restored.load_state_dict(agent.state_dict())
    assert all(torch.equal(v, agent.averaged.state_dict()[k]) for k, v in restored.averaged.state_dict().items())
    plain = DoubleDQN((4,), 3, _cfg())
    assert plain.policy_net is plain.online and "averaged" not in plain.state_dict()
    restored.load_state_dict(plain.state_dict())
    assert all(torch.equal(v, plain.online.state_dict()[k]) for k, v in restored.averaged.state_dict().items())


def test_learning_rate_follows_the_env_step_schedule():
    from laneshift.learner.loop import linear_schedule

    assert linear_schedule(1e-3, 1e-4, 0, 100) == pytest.approx(1e-3)
    assert linear_schedule(1e-3, 1e-4, 50, 100) == pytest.approx(5.5e-4)
    assert linear_schedule(1e-3, 1e-4, 100, 100) == pytest.approx(1e-4)
    assert linear_schedule(1e-3, 1e-4, 250, 100) == pytest.approx(1e-4)  # past the budget: stays at the end value
    agent = DoubleDQN((4,), 3, _cfg(lr=1e-3))
    agent.set_lr(2e-4)
    assert agent.lr == pytest.approx(2e-4)
    before = next(agent.online.parameters()).detach().clone()
    agent.set_lr(0.0)
    agent.update(_random_batch(np.random.default_rng(1)))
    assert torch.equal(before, next(agent.online.parameters()))  # a zero step size moves nothing


def test_schedule_and_average_options_are_checked():
    from laneshift.config import ConfigError

    with pytest.raises(ConfigError, match="learner.lr_final"):
        LearnerConfig(lr=1e-4, lr_final=1e-3)
    with pytest.raises(ConfigError, match="learner.ema_decay"):
        LearnerConfig(ema_decay=1.0)
    with pytest.raises(ConfigError, match="learner.terminal_value"):
        LearnerConfig(terminal_value=float("nan"))
    with pytest.raises(ConfigError, match="learner.imitation_final"):
        LearnerConfig(imitation_final=1.5)
    with pytest.raises(ConfigError, match="learner.imitation_fade_steps"):
        LearnerConfig(imitation_fade_steps=-1)


# --------------------------------------------------------------------------- weights


def _net(hidden=(8, 8), obs=4, n=3, seed=0) -> torch.nn.Module:
    torch.manual_seed(seed)
    return build_q_network((obs,), n, hidden)


def _arrays(net: torch.nn.Module) -> dict[str, np.ndarray]:
    return {k: v.detach().numpy().copy() for k, v in net.state_dict().items()}


def test_to_wire_decode_load_into_round_trip():
    src, dst = _net(seed=1), _net(seed=2)
    assert tensors_digest(_arrays(src)) != tensors_digest(_arrays(dst))
    w = wire.decode_weights(to_wire(src, version=7, phase=2, updates=1234))
    assert (w.version, w.phase, w.updates) == (7, 2, 1234)
    load_into(dst, w.tensors)
    assert tensors_digest(_arrays(dst)) == tensors_digest(_arrays(src))
    x = torch.randn(5, 4)
    assert torch.equal(src(x), dst(x))


def test_load_into_is_strict():
    net = _net()
    good = _arrays(net)
    with pytest.raises(ValueError, match="do not match"):
        load_into(net, {k: v for k, v in good.items() if k != "net.0.bias"})
    with pytest.raises(ValueError, match="do not match"):
        load_into(net, {**good, "extra": np.zeros(1, np.float32)})
    with pytest.raises(ValueError, match="shape"):
        load_into(net, {**good, "net.0.weight": np.zeros((8, 5), np.float32)})
    with pytest.raises(ValueError):
        load_into(net, _arrays(_net(hidden=(16,))))
    before = tensors_digest(_arrays(net))
    assert tensors_digest(_arrays(net)) == before == tensors_digest(good)  # refusals changed nothing


def test_policy_refuses_weights_for_another_network():
    p = QPolicy((4,), 3, hidden=(8, 8))
    with pytest.raises(ValueError):
        p.load(wire.decode_weights(to_wire(_net(hidden=(16,)), 1, 0, 0)))
    assert p.version == -1


def test_checkpoint_save_load(tmp_path):
    net = _net(seed=3)
    path = save_checkpoint(net, tmp_path / "ck" / "latest.safetensors", {"version": 4, "updates": 99, "lr": 0.5})
    assert path.exists() and not path.with_suffix(".tmp").exists()
    tensors, meta = load_checkpoint(path)
    assert meta == {"version": "4", "updates": "99", "lr": "0.5"}
    assert tensors_digest(tensors) == tensors_digest(_arrays(net))
    # a plain safetensors file: the reference loader reads it
    loaded = load_file(str(path))
    assert set(loaded) == set(net.state_dict())
    for k, v in net.state_dict().items():
        assert torch.equal(loaded[k], v)
    fresh = _net(seed=9)
    fresh.load_state_dict(loaded)
    assert torch.equal(fresh(torch.ones(1, 4)), net(torch.ones(1, 4)))


def test_checkpoint_overwrite_is_atomic_replace(tmp_path):
    path = tmp_path / "c.safetensors"
    save_checkpoint(_net(seed=1), path, {})
    save_checkpoint(_net(seed=2), path, {})
    assert tensors_digest(load_checkpoint(path)[0]) == tensors_digest(_arrays(_net(seed=2)))


def test_tensors_digest():
    a = {"x": np.arange(4, dtype=np.float32), "y": np.ones((2, 2), np.float32)}
    assert tensors_digest(a) == tensors_digest(dict(reversed(list(a.items()))))  # name order, not dict order
    assert tensors_digest(a) == tensors_digest({k: v.copy() for k, v in a.items()})
    assert tensors_digest(a) != tensors_digest({**a, "y": np.full((2, 2), 1.0 + 1e-7, np.float32)})
    assert tensors_digest(a) != tensors_digest({"z": a["x"], "y": a["y"]})
    assert tensors_digest(a) != tensors_digest({**a, "x": a["x"].astype(np.float64)})
    nc = np.asfortranarray(np.arange(6, dtype=np.float32).reshape(2, 3))
    assert tensors_digest({"m": nc}) == tensors_digest({"m": np.ascontiguousarray(nc)})
    assert len(tensors_digest(a)) == 64


# --------------------------------------------------------------------------- exploration


def test_linear_schedule_endpoints():
    s = make_schedule(ActorConfig(exploration="linear", epsilon_start=1.0, epsilon_final=0.1,
                                  epsilon_decay_steps=1000), worker_index=3)
    assert s(0) == 1.0
    assert s(500) == pytest.approx(0.55)
    assert s(1000) == pytest.approx(0.1)
    assert s(10**9) == pytest.approx(0.1)
    vals = [s(t) for t in range(0, 1200, 50)]
    assert all(a >= b for a, b in zip(vals, vals[1:]))


def test_exponential_schedule_has_a_floor():
    cfg = ActorConfig(exploration="exponential", epsilon_start=1.0, epsilon_final=0.05, epsilon_decay_rate=0.01)
    s = make_schedule(cfg, 0)
    assert s(0) == 1.0
    assert s(10) == pytest.approx(0.99**10)
    assert s(100) == pytest.approx(0.99**100)
    assert s(10_000) == 0.05 and s(10**7) == 0.05
    assert make_schedule(ActorConfig(exploration="exponential", epsilon_decay_rate=0.0), 0)(10**6) == 1.0


def test_held_exploration_holds_each_random_action_for_its_drawn_duration():
    """ez-greedy: a random action starts with probability epsilon and is held for n ~ zeta(mu) steps
    (cut at hold_max); the greedy action otherwise; a new episode ends the hold."""
    rng = np.random.default_rng(0)
    h = HeldExploration(n_envs=1, n_actions=9, mu=2.0, hold_max=100, rng=rng)
    assert all(int(h.act(np.array([4]), epsilon=0.0)[0]) == 4 for _ in range(50))
    # Count the holds' lengths: a hold starts whenever no action is held (epsilon 1).
    lengths, n = [], 0
    for _ in range(20_000):
        started = h.left[0] == 0
        h.act(np.array([4]), epsilon=1.0)
        if started and n:
            lengths.append(n)
        if started:
            n = 0
        n += 1
    weights = np.arange(1, 101, dtype=np.float64) ** -2.0
    expected_mean = float((np.arange(1, 101) * weights).sum() / weights.sum())  # about 3.2
    assert np.mean(lengths) == pytest.approx(expected_mean, rel=0.1)
    assert max(lengths) <= 100
    assert np.mean(np.array(lengths) == 1) == pytest.approx(weights[0] / weights.sum(), abs=0.03)
    # Held: the same action on every step of a hold.
    h = HeldExploration(n_envs=2, n_actions=9, mu=1.5, hold_max=50, rng=np.random.default_rng(1))
    seen = np.array([h.act(np.array([4, 4]), epsilon=0.2) for _ in range(500)])
    assert (seen != 4).any()
    h.act(np.array([4, 4]), epsilon=1.0)
    h.end_episode(0)
    assert h.left[0] == 0 and int(h.act(np.array([3, 3]), epsilon=0.0)[0]) == 3


def test_held_exploration_is_refused_without_a_zeta_exponent():
    with pytest.raises(ValueError, match="mu must be > 1"):
        HeldExploration(n_envs=1, n_actions=9, mu=1.0, hold_max=10, rng=np.random.default_rng(0))
    with pytest.raises(ConfigError, match="actor.hold_mu"):
        ActorConfig(hold_mu=0.5)
    with pytest.raises(ConfigError, match="actor.hold_max"):
        ActorConfig(hold_mu=2.0, hold_max=0)


def test_apex_per_worker_epsilons():
    """Ape-X (Horgan et al. 2018): eps_i = eps ** (1 + alpha * i / (N - 1)), eps 0.4, alpha 7."""
    n = 8
    cfg = ActorConfig(exploration="apex", workers=n, apex_epsilon=0.4, apex_alpha=7.0)
    eps = [make_schedule(cfg, i)(0) for i in range(n)]
    for i, e in enumerate(eps):
        assert e == pytest.approx(0.4 ** (1 + 7.0 * i / (n - 1)))
    assert eps[0] == pytest.approx(0.4) and eps[-1] == pytest.approx(0.4**8)
    assert all(a > b for a, b in zip(eps, eps[1:]))
    assert make_schedule(cfg, 2)(0) == make_schedule(cfg, 2)(10**6)  # fixed over time
    single = ActorConfig(exploration="apex", workers=1, apex_epsilon=0.3)
    assert make_schedule(single, 0)(0) == 0.3


# --------------------------------------------------------------------------- policy


def test_policy_greedy_at_epsilon_zero():
    p = QPolicy((4,), 5, hidden=(8,), seed=0)
    net = _net(hidden=(8,), obs=4, n=5, seed=4)
    p.load(wire.decode_weights(to_wire(net, 3, 2, 10)))
    assert (p.version, p.phase) == (3, 2)
    obs = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)
    with torch.no_grad():
        expected = net(torch.as_tensor(obs)).argmax(dim=1).numpy()
    assert np.array_equal(p.act(obs, 0.0), expected)
    assert np.array_equal(p.greedy(obs), expected)


def test_policy_uniform_at_epsilon_one():
    p = QPolicy((2,), 4, hidden=(8,), seed=1)
    net = _net(hidden=(8,), obs=2, n=4, seed=1)
    with torch.no_grad():
        _set_constant_q(net, [0.0, 0.0, 9.0, 0.0])  # greedy is always action 2
    p.load_tensors({k: v.numpy() for k, v in net.state_dict().items()})
    obs = np.zeros((4000, 2), np.float32)
    actions = p.act(obs, 1.0)
    counts = np.bincount(actions, minlength=4)
    assert counts.sum() == 4000 and actions.min() >= 0 and actions.max() < 4
    chi2 = float(((counts - 1000) ** 2 / 1000).sum())
    assert chi2 < 16.27, counts  # chi-square, 3 dof, p = 0.001
    half = np.bincount(p.act(obs, 0.5), minlength=4)
    assert abs(half[2] / 4000 - (0.5 + 0.5 / 4)) < 0.03  # greedy share = 1 - eps + eps / n


def test_policy_is_seeded():
    obs = np.zeros((100, 3), np.float32)
    a = QPolicy((3,), 6, hidden=(4,), seed=5).act(obs, 1.0)
    b = QPolicy((3,), 6, hidden=(4,), seed=5).act(obs, 1.0)
    c = QPolicy((3,), 6, hidden=(4,), seed=6).act(obs, 1.0)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_margin_loss_makes_the_demonstrators_action_greedy_on_demo_rows():
    """DQfD's large-margin loss alone (rewards all zero, so TD says nothing) teaches the demo action."""
    import numpy as np

    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    rng = np.random.default_rng(0)
    obs = rng.normal(size=(64, 4)).astype(np.float32)
    expert = (obs[:, 0] > 0).astype(np.int64) * 2  # the demonstrator's rule: action 2 if x0 > 0 else 0
    batch = {"obs": obs, "action": expert, "reward": np.zeros(64, np.float32), "next_obs": obs,
             "terminated": np.ones(64, np.uint8), "steps": np.ones(64, np.uint8), "weight": np.ones(64, np.float32),
             "is_demo": np.ones(64, np.uint8)}
    off = DoubleDQN((4,), 3, LearnerConfig(hidden=(32,), lr=1e-2, seed=1))
    on = DoubleDQN((4,), 3, LearnerConfig(hidden=(32,), lr=1e-2, seed=1, margin_loss_weight=1.0))
    for _ in range(300):
        off.update(batch)
        metrics = on.update(batch)
    assert (on.greedy(obs) == expert).mean() == 1.0
    assert metrics["margin_loss"] < 0.05
    assert (off.greedy(obs) == expert).mean() < 0.9  # TD on zero rewards alone does not
    # Agent rows are unaffected by the margin term.
    agent = {**batch, "is_demo": np.zeros(64, np.uint8)}
    assert on.update(agent)["margin_loss"] == 0.0


def test_cross_entropy_on_demo_rows_teaches_the_demonstrators_action_through_a_dueling_head():
    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    rng = np.random.default_rng(1)
    obs = rng.normal(size=(64, 4)).astype(np.float32)
    expert = (obs[:, 1] > 0).astype(np.int64)  # action 1 if x1 > 0 else 0
    batch = {"obs": obs, "action": expert, "reward": np.zeros(64, np.float32), "next_obs": obs,
             "terminated": np.ones(64, np.uint8), "steps": np.ones(64, np.uint8), "weight": np.ones(64, np.float32),
             "is_demo": np.ones(64, np.uint8)}
    agent = DoubleDQN((4,), 3, LearnerConfig(hidden=(32,), lr=1e-2, seed=1, bc_loss_weight=1.0, dueling=True))
    for _ in range(300):
        metrics = agent.update(batch)
    assert (agent.greedy(obs) == expert).mean() == 1.0
    assert metrics["bc_loss"] < 0.1 and metrics["margin_loss"] == 0.0
    # Rows not from the demos get no imitation term.
    plain = DoubleDQN((4,), 3, LearnerConfig(hidden=(32,), seed=1, bc_loss_weight=1.0, dueling=True))
    assert plain.update({**batch, "is_demo": np.zeros(64, np.uint8)})["bc_loss"] == 0.0


def test_the_imitation_scale_weighs_both_imitation_losses_and_zero_leaves_the_td_loss_alone():
    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    rng = np.random.default_rng(2)
    obs = rng.normal(size=(32, 4)).astype(np.float32)
    batch = {"obs": obs, "action": rng.integers(0, 3, 32), "reward": rng.normal(size=32).astype(np.float32),
             "next_obs": rng.normal(size=(32, 4)).astype(np.float32), "terminated": np.zeros(32, np.uint8),
             "steps": np.ones(32, np.uint8), "weight": np.ones(32, np.float32), "is_demo": np.ones(32, np.uint8)}
    imitating = dict(hidden=(16,), seed=3, dueling=True, margin_loss_weight=1.0, bc_loss_weight=1.0)
    faded, plain = DoubleDQN((4,), 3, LearnerConfig(**imitating)), DoubleDQN((4,), 3, LearnerConfig(hidden=(16,), seed=3,
                                                                                                  dueling=True))
    faded.imitation_scale = 0.0
    for _ in range(5):
        m_faded, m_plain = faded.update(batch), plain.update(batch)
    # At 0 the update is the TD update of a learner without imitation losses, step for step.
    assert m_faded["loss"] == m_plain["loss"] and m_faded["bc_loss"] == m_faded["margin_loss"] == 0.0
    assert all(torch.equal(a, b) for a, b in zip(faded.online.parameters(), plain.online.parameters()))
    # At 0.5 the loss is the TD loss plus half of each imitation loss.
    half, whole = DoubleDQN((4,), 3, LearnerConfig(**imitating)), DoubleDQN((4,), 3, LearnerConfig(**imitating))
    half.imitation_scale = 0.5
    m_half, m_whole = half.update(batch), whole.update(batch)
    assert m_half["bc_loss"] == m_whole["bc_loss"] > 0 and m_half["margin_loss"] == m_whole["margin_loss"] > 0
    td = m_whole["loss"] - m_whole["bc_loss"] - m_whole["margin_loss"]
    assert m_half["loss"] == pytest.approx(td + 0.5 * (m_whole["bc_loss"] + m_whole["margin_loss"]), rel=1e-5)


def test_an_imitation_only_update_trains_the_imitation_losses_alone_and_never_reads_the_next_observations():
    """learner.phase1_td=false's update (agent.td_loss off): the loss is the weighted imitation losses,
    nothing else; the next observations and the target network play no part (NaN there changes nothing)."""
    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    rng = np.random.default_rng(4)
    obs = rng.normal(size=(64, 4)).astype(np.float32)
    expert = (obs[:, 2] > 0).astype(np.int64) * 2
    batch = {"obs": obs, "action": expert, "reward": rng.normal(size=64).astype(np.float32),
             "next_obs": np.full((64, 4), np.nan, np.float32), "terminated": np.zeros(64, np.uint8),
             "steps": np.ones(64, np.uint8), "weight": np.ones(64, np.float32), "is_demo": np.ones(64, np.uint8)}
    cfg = LearnerConfig(hidden=(32,), lr=1e-2, seed=5, dueling=True, margin_loss_weight=0.5, bc_loss_weight=2.0,
                        target_update_period=1000)
    agent = DoubleDQN((4,), 3, cfg)
    target_before = [p.clone() for p in agent.target.parameters()]
    agent.td_loss = False
    for _ in range(200):
        metrics = agent.update(batch)
    assert math.isfinite(metrics["loss"]) and metrics["td_abs"] == 0.0
    assert metrics["loss"] == pytest.approx(0.5 * metrics["margin_loss"] + 2.0 * metrics["bc_loss"], rel=1e-5)
    assert (agent.greedy(obs) == expert).mean() == 1.0
    assert agent.updates == 200 and all(torch.equal(a, b) for a, b in zip(agent.target.parameters(), target_before))
    # A batch sampled without next observations (SampleRequest(next_obs=False)) serves it alike.
    without = {k: v for k, v in batch.items() if k != "next_obs"}
    assert math.isfinite(agent.update(without)["loss"])
    # The same agent with the TD loss back on reads the next observations again (here: NaN), and
    # refuses a batch without them in one clear line.
    agent.td_loss = True
    assert math.isnan(agent.update(batch)["loss"])
    with pytest.raises(ValueError, match="TD loss needs next_obs"):
        agent.update(without)


def test_the_full_update_is_unchanged_by_the_imitation_losses_refactor():
    """TD + imitation: the loss is the TD loss plus each weighted imitation loss (the figures an
    imitation-only update of the same batch gives for the imitation part)."""
    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    rng = np.random.default_rng(6)
    obs = rng.normal(size=(32, 4)).astype(np.float32)
    batch = {"obs": obs, "action": rng.integers(0, 3, 32), "reward": rng.normal(size=32).astype(np.float32),
             "next_obs": rng.normal(size=(32, 4)).astype(np.float32), "terminated": np.zeros(32, np.uint8),
             "steps": np.ones(32, np.uint8), "weight": np.ones(32, np.float32),
             "is_demo": (np.arange(32) % 2).astype(np.uint8)}
    cfg = LearnerConfig(hidden=(16,), seed=7, margin_loss_weight=1.0, bc_loss_weight=3.0)
    full, imitation = DoubleDQN((4,), 3, cfg), DoubleDQN((4,), 3, cfg)
    imitation.td_loss = False
    m_full, m_imitation = full.update(batch), imitation.update(batch)
    assert (m_full["margin_loss"], m_full["bc_loss"]) == (m_imitation["margin_loss"], m_imitation["bc_loss"])
    assert m_full["margin_loss"] > 0 and m_full["bc_loss"] > 0
    assert m_full["loss"] > m_imitation["loss"] == pytest.approx(m_full["margin_loss"] + 3.0 * m_full["bc_loss"],
                                                                 rel=1e-5)


def test_phase1_td_false_needs_an_imitation_loss_and_the_uniform_sampler():
    from laneshift.config import ConfigError, LearnerConfig, ReplayConfig, RunConfig

    with pytest.raises(ConfigError, match="learner.phase1_td"):
        LearnerConfig(phase1_td=False)
    assert not LearnerConfig(phase1_td=False, bc_loss_weight=1.0).phase1_td
    learner = LearnerConfig(phase1_td=False, bc_loss_weight=1.0)
    with pytest.raises(ConfigError, match="learner.phase1_td.*prioritized"):
        RunConfig(learner=learner, replay=ReplayConfig(sampler="prioritized"))
    assert RunConfig(learner=learner).learner.phase1_td is False


def test_heads_per_road_checkpoints_load_back_with_their_heads(tmp_path):
    from laneshift.tools.studies.evaluate import load_greedy_policy
    from laneshift.qnet import build_q_network
    from laneshift.qnet import save_checkpoint

    torch.manual_seed(0)
    net = build_q_network((9,), 9, (16,), dueling=True, heads=4)
    path = save_checkpoint(net, tmp_path / "h.safetensors", {"obs_shape": "9", "hidden": "16", "n_actions": 9,
                                                             "dueling": 1, "heads": 4})
    greedy = load_greedy_policy(path)
    rng = np.random.default_rng(0)
    for road in range(4):
        obs = np.concatenate([rng.normal(size=5), np.eye(4)[road]]).astype(np.float32)
        with torch.no_grad():
            assert greedy(obs) == int(net(torch.as_tensor(obs)[None]).argmax())


def test_a_learner_with_one_head_per_road_learns_each_roads_own_action():
    from laneshift.config import LearnerConfig
    from laneshift.learner.dqn import DoubleDQN

    # The same features, a different best action per road: only the road's one-hot tells them apart.
    rng = np.random.default_rng(0)
    n = 256
    roads = rng.integers(0, 4, size=n)
    obs = np.concatenate([rng.normal(size=(n, 4)), np.eye(4)[roads]], axis=1).astype(np.float32)
    expert = (roads * 2).astype(np.int64)  # road r's demonstrator drives action 2r
    batch = {"obs": obs, "action": expert, "reward": np.zeros(n, np.float32), "next_obs": obs,
             "terminated": np.ones(n, np.uint8), "is_demo": np.ones(n, np.uint8), "steps": np.ones(n, np.uint8),
             "weight": np.ones(n, np.float32)}
    agent = DoubleDQN((8,), 9, LearnerConfig(hidden=(32,), lr=1e-2, seed=0, bc_loss_weight=1.0, dueling=True,
                                             heads=4))
    for _ in range(300):
        agent.update(batch)
    assert (agent.greedy(obs) == expert).mean() == 1.0


def test_dueling_checkpoints_load_back_as_dueling_policies(tmp_path):
    from laneshift.tools.studies.evaluate import load_greedy_policy
    from laneshift.qnet import DuelingHead, build_q_network
    from laneshift.qnet import save_checkpoint

    net = build_q_network((5,), 9, (16,), dueling=True)
    assert isinstance(net.net[-1], DuelingHead)
    path = save_checkpoint(net, tmp_path / "d.safetensors", {"obs_shape": "5", "hidden": "16", "n_actions": 9,
                                                             "dueling": 1})
    greedy = load_greedy_policy(path)
    obs = np.random.default_rng(0).normal(size=5).astype(np.float32)
    with torch.no_grad():
        assert greedy(obs) == int(net(torch.as_tensor(obs)[None]).argmax())
