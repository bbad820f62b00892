"""DoubleDQN.update pinned against a reference written here the slow, obvious way: a Python loop
over rows for the loss (Double DQN target, n-step discount, terminals, importance weights, the
DQfD margin and the imitation cross-entropy on demo rows), hand-written global-norm clipping and
hand-written Adam with L2 weight decay. Same seed, same start: the optimized update must give the
same loss, metrics, per-row |TD error|, gradients and parameters (allclose) after a step, for
three steps in a row (Adam's state carried over, a hard target sync after the second), each step
started from the same state. CPU, tiny nets, no sleeps.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch

from laneshift.config import LearnerConfig
from laneshift.learner.dqn import METRIC_NAMES, DoubleDQN, UpdateMetrics

torch.set_num_threads(1)


# --------------------------------------------------------------------------- the reference


class Reference:
    """The same Double DQN learner, written for reading, not for speed."""

    def __init__(self, online: torch.nn.Module, target: torch.nn.Module, cfg: LearnerConfig):
        self.online, self.target, self.cfg = copy.deepcopy(online), copy.deepcopy(target), cfg
        self.params = list(self.online.parameters())
        self.m = [torch.zeros_like(p) for p in self.params]
        self.v = [torch.zeros_like(p) for p in self.params]
        self.t = 0
        self.updates = 0

    def loss(self, b: dict[str, np.ndarray]) -> tuple[torch.Tensor, dict[str, float], list[float]]:
        cfg = self.cfg
        rows = len(b["action"])
        td_loss, margins, ces, td_abs, qs = [], [], [], [], []
        for i in range(rows):
            q_s = self.online(torch.as_tensor(b["obs"][i:i + 1]))[0]  # Q(s_i, .), with grad
            a = int(b["action"][i])
            q = q_s[a]
            with torch.no_grad():
                q_next_target = self.target(torch.as_tensor(b["next_obs"][i:i + 1]))[0]
                if cfg.double:  # online picks, target values
                    a_next = int(torch.argmax(self.online(torch.as_tensor(b["next_obs"][i:i + 1]))[0]))
                    v_next = float(q_next_target[a_next])
                else:
                    v_next = float(q_next_target.max())
                bootstrap = 0.0 if b["terminated"][i] else cfg.gamma ** int(b["steps"][i]) * v_next
                y = float(b["reward"][i]) + bootstrap
            d = q - y
            if abs(float(d.detach())) < cfg.huber_delta:
                huber = 0.5 * d * d
            else:
                huber = cfg.huber_delta * (d.abs() - 0.5 * cfg.huber_delta)
            w = float(b["weight"][i]) if "weight" in b else 1.0
            td_loss.append(w * huber)
            td_abs.append(abs(float(d.detach())))
            qs.append(float(q.detach()))
            if "is_demo" in b and b["is_demo"][i]:
                bonus = torch.tensor([0.0 if j == a else cfg.margin for j in range(len(q_s))])
                margins.append(torch.max(q_s + bonus) - q)
                ces.append(-torch.log_softmax(q_s, dim=0)[a])
        loss = sum(td_loss) / rows
        margin = sum(margins) / len(margins) if margins and cfg.margin_loss_weight > 0 else torch.tensor(0.0)
        bc = sum(ces) / len(ces) if ces and cfg.bc_loss_weight > 0 else torch.tensor(0.0)
        total = loss + cfg.margin_loss_weight * margin + cfg.bc_loss_weight * bc
        metrics = {"loss": float(total.detach()), "q_mean": sum(qs) / rows, "td_abs": sum(td_abs) / rows,
                   "margin_loss": float(margin.detach()), "bc_loss": float(bc.detach())}
        return total, metrics, td_abs

    def update(self, b: dict[str, np.ndarray]) -> tuple[dict[str, float], list[float]]:
        cfg = self.cfg
        total, metrics, td_abs = self.loss(b)
        for p in self.params:
            p.grad = None
        total.backward()
        grads = [p.grad.clone() for p in self.params]
        norm = math.sqrt(sum(float((g.double() ** 2).sum()) for g in grads))
        metrics["grad_norm"] = norm
        scale = min(1.0, cfg.grad_clip / (norm + 1e-6))
        self.t += 1
        with torch.no_grad():
            for i, p in enumerate(self.params):
                g = grads[i] * scale
                p.grad = g.clone()  # what the optimized learner leaves in .grad: the clipped gradient
                g = g + cfg.weight_decay * p  # Adam's coupled L2
                self.m[i] = 0.9 * self.m[i] + 0.1 * g
                self.v[i] = 0.999 * self.v[i] + 0.001 * g * g
                m_hat = self.m[i] / (1 - 0.9 ** self.t)
                v_hat = self.v[i] / (1 - 0.999 ** self.t)
                p -= cfg.lr * m_hat / (v_hat.sqrt() + 1e-8)
        self.updates += 1
        if self.updates % cfg.target_update_period == 0:
            self.target.load_state_dict(self.online.state_dict())
        return metrics, td_abs

    @torch.no_grad()
    def sync_from(self, agent: DoubleDQN) -> None:
        """Start the next step from the agent's exact state (parameters, target, Adam moments), so
        that every step is compared from one start and float32 noise does not compound."""
        for p, q in zip(self.params, agent.online.parameters()):
            p.copy_(q)
        self.target.load_state_dict(agent.target.state_dict())
        for i, q in enumerate(agent.online.parameters()):
            state = agent.optimizer.state[q]
            self.m[i], self.v[i] = state["exp_avg"].clone(), state["exp_avg_sq"].clone()
            assert int(state["step"]) == self.t


# --------------------------------------------------------------------------- batches and cases


def _batch(rng: np.random.Generator, rows: int, obs_shape: tuple[int, ...], n_actions: int, demos: bool,
           frames: bool) -> dict[str, np.ndarray]:
    if frames:
        obs, next_obs = (rng.integers(0, 256, (rows, *obs_shape), dtype=np.uint8) for _ in range(2))
    else:
        obs, next_obs = (rng.standard_normal((rows, *obs_shape), dtype=np.float32) for _ in range(2))
    b = {"obs": obs, "next_obs": next_obs, "action": rng.integers(0, n_actions, rows).astype(np.int64),
         "reward": rng.standard_normal(rows, dtype=np.float32) * 2,
         "terminated": (rng.random(rows) < 0.3).astype(np.uint8),
         "steps": rng.integers(1, 4, rows).astype(np.uint8),  # n-step items, n = 1..3
         "weight": rng.uniform(0.2, 1.5, rows).astype(np.float32)}
    if demos:
        b["is_demo"] = (rng.random(rows) < 0.5).astype(np.uint8)
    return b


CASES = {
    "double": dict(obs=(6,), cfg={}),
    "vanilla": dict(obs=(6,), cfg={"double": False}),
    "clipped-l2": dict(obs=(6,), cfg={"grad_clip": 0.05, "weight_decay": 1e-2, "huber_delta": 0.5}),
    "demos-dueling": dict(obs=(6,), demos=True,
                          cfg={"dueling": True, "margin_loss_weight": 0.7, "bc_loss_weight": 0.3, "hidden": (16, 16)}),
    "demos-off": dict(obs=(6,), demos=True, cfg={}),  # demo rows, demo losses off: plain TD
    "cnn-frames": dict(obs=(2, 36, 36), frames=True, cfg={"dueling": True}),
}


def _assert_params_close(got: np.ndarray, want: np.ndarray, lr: float, step: int, name: str) -> None:
    """Parameters equal to 1 % of one Adam step (lr). Adam moves each element by about
    lr * g / |g|, so float32 noise on a gradient element that is near zero by cancellation
    (batched vs row-by-row sums) can move that one element by a visible fraction of lr: up to
    1 in 10,000 elements (none in a net under 10,000 parameters) may differ, by at most the
    2 * lr that a flipped sign would cost. A real difference in the loss moves far more."""
    bad = ~np.isclose(got, want, rtol=1e-5, atol=lr / 100)
    assert bad.sum() <= got.size // 10_000, (step, name, bad.sum(), float(np.abs(got - want).max()))
    assert np.abs(got - want).max() <= 2 * lr, (step, name)


@pytest.mark.parametrize("concat", [False, True], ids=["two-passes", "one-concat-pass"])
@pytest.mark.parametrize("name", list(CASES))
def test_update_matches_the_reference(name: str, concat: bool) -> None:
    case = CASES[name]
    n_actions, rows = 5, 12
    cfg = LearnerConfig(**{"hidden": (32,), "batch_size": rows, "seed": 3, "lr": 1e-2, "gamma": 0.9,
                           "target_update_period": 2, "device": "cpu", **case["cfg"]})
    agent = DoubleDQN(case["obs"], n_actions, cfg)
    if concat:  # the CUDA path (one online pass over cat(obs, next_obs)), checked on CPU
        agent.concat_online_pass = True
    # A target that differs from the online net from the start, so the double target matters.
    with torch.no_grad():
        for p in agent.target.parameters():
            p.add_(0.1 * torch.randn_like(p))
    ref = Reference(agent.online, agent.target, cfg)
    rng = np.random.default_rng(7)
    for step in range(1, 4):  # three updates: Adam's state carries over, the target syncs after 2
        b = _batch(rng, rows, case["obs"], n_actions, case.get("demos", False), case.get("frames", False))
        got = agent.update(b)
        want, want_td = ref.update(b)
        assert isinstance(got, UpdateMetrics) and set(got) == set(METRIC_NAMES)
        for k in METRIC_NAMES:
            assert got[k] == pytest.approx(want[k], rel=1e-4, abs=1e-5), (step, k)
        np.testing.assert_allclose(agent.last_td_abs, want_td, rtol=1e-4, atol=1e-5)
        for (pname, p), q in zip(agent.online.named_parameters(), ref.params):
            np.testing.assert_allclose(p.grad.numpy(), q.grad.numpy(), rtol=1e-4, atol=1e-6, err_msg=f"{step} {pname}")
            _assert_params_close(p.detach().numpy(), q.detach().numpy(), cfg.lr, step, pname)
        for (pname, p), q in zip(agent.target.state_dict().items(), ref.target.state_dict().values()):
            _assert_params_close(p.numpy(), q.numpy(), cfg.lr, step, f"target {pname}")
        ref.sync_from(agent)
    assert agent.updates == ref.updates == 3
    if case.get("demos") and cfg.margin_loss_weight > 0:
        assert got["margin_loss"] > 0 and got["bc_loss"] > 0  # the demo terms were exercised


def test_metrics_are_read_back_once_and_only_when_read() -> None:
    agent = DoubleDQN((4,), 3, LearnerConfig(hidden=(8,), batch_size=4, device="cpu"))
    b = _batch(np.random.default_rng(0), 4, (4,), 3, demos=False, frames=False)
    m = agent.update(b)
    assert m._floats is None  # nothing converted yet
    assert isinstance(m.tensor(), torch.Tensor) and m.tensor().shape == (len(METRIC_NAMES),)
    assert isinstance(m["loss"], float) and m.get("q_mean") == m["q_mean"] and m.get("nope") is None
    assert dict(m) == {k: m[k] for k in METRIC_NAMES}


def test_a_state_saved_by_another_adam_implementation_loads_into_this_ones(tmp_path) -> None:
    """A learner state written before the optimizer flags changed (foreach/fused None) restores
    into the optimizer this code chose, with its moments intact."""
    cfg = LearnerConfig(hidden=(8,), batch_size=4, device="cpu")
    a = DoubleDQN((4,), 3, cfg)
    b = _batch(np.random.default_rng(0), 4, (4,), 3, demos=False, frames=False)
    a.update(b)
    state = a.state_dict()
    for group in state["optimizer"]["param_groups"]:
        group.update(fused=None, foreach=None)
    torch.save(state, tmp_path / "s.pt")
    c = DoubleDQN((4,), 3, cfg)
    c.load_state_dict(torch.load(tmp_path / "s.pt", weights_only=True))
    chosen = {k: a.optimizer.param_groups[0][k] for k in ("fused", "foreach")}
    assert chosen == {"fused": True, "foreach": None}  # CPU: fused Adam (dqn._ADAM_IMPL)
    assert all({k: g[k] for k in chosen} == chosen for g in c.optimizer.param_groups)
    ma, mc = a.update(b), c.update(b)
    assert ma["loss"] == mc["loss"]
    for p, q in zip(a.online.parameters(), c.online.parameters()):
        assert torch.equal(p, q)
