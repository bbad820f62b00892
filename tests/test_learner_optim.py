"""learner/optim.py: the learner's Adam is torch's Adam, number for number, without importing
torch._dynamo (1.1 s of the learner's start-up and 73 MB on the dev machine).

Room: tests, unit. May import: laneshift.learner.optim, torch, pytest, the standard library."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest
import torch

from laneshift.learner.optim import AVOIDS_DYNAMO, EagerAdam


def _train(opt_cls: type, impl: dict, steps: int = 40) -> tuple[list[torch.Tensor], dict]:
    torch.manual_seed(3)
    net = torch.nn.Sequential(torch.nn.Linear(12, 32), torch.nn.ReLU(), torch.nn.Linear(32, 5))
    opt = opt_cls(net.parameters(), lr=3e-3, weight_decay=1e-4, **impl)
    gen = torch.Generator().manual_seed(7)
    for _ in range(steps):
        x, y = torch.randn(64, 12, generator=gen), torch.randn(64, 5, generator=gen)
        loss = torch.nn.functional.mse_loss(net(x), y)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return [p.detach().clone() for p in net.parameters()], opt.state_dict()


@pytest.mark.parametrize("impl", [{"fused": True}, {"foreach": True}, {"foreach": False}],
                         ids=["fused", "foreach", "for-loop"])
def test_eager_adam_is_torch_adam_bitwise(impl):
    theirs, their_state = _train(torch.optim.Adam, impl)
    ours, our_state = _train(EagerAdam, impl)
    for a, b in zip(theirs, ours):
        assert torch.equal(a, b)
    assert our_state["param_groups"] == their_state["param_groups"]
    for k, s in their_state["state"].items():
        for name, value in s.items():
            assert torch.equal(value, our_state["state"][k][name]), name


def test_eager_adam_loads_a_torch_adam_state():
    """A learner state written with torch.optim.Adam (earlier revisions) goes on unchanged."""
    _, state = _train(torch.optim.Adam, {"fused": True}, steps=5)
    torch.manual_seed(3)
    net = torch.nn.Sequential(torch.nn.Linear(12, 32), torch.nn.ReLU(), torch.nn.Linear(32, 5))
    opt = EagerAdam(net.parameters(), lr=3e-3, weight_decay=1e-4, fused=True)
    opt.load_state_dict(state)
    assert int(opt.state_dict()["state"][0]["step"]) == 5


def test_the_learner_never_imports_torch_dynamo():
    """A whole DoubleDQN life in a fresh process: build, update, save, load, reset, act."""
    assert AVOIDS_DYNAMO, "this torch's optimizer has another shape: learner/optim.py patches nothing"
    code = textwrap.dedent("""
        import sys
        import numpy as np
        from laneshift.config import LearnerConfig
        from laneshift.learner.dqn import DoubleDQN
        agent = DoubleDQN((8,), 3, LearnerConfig(hidden=(16,), batch_size=4))
        rng = np.random.default_rng(0)
        b = dict(obs=rng.random((4, 8), np.float32), action=np.zeros(4, np.int64), reward=np.ones(4, np.float32),
                 next_obs=rng.random((4, 8), np.float32), terminated=np.zeros(4, np.uint8), steps=np.ones(4, np.uint8))
        for _ in range(3):
            dict(agent.update(b))
        agent.load_state_dict(agent.state_dict())
        agent.reset_optimizer()
        agent.update(b)
        agent.greedy(b["obs"])
        print("torch._dynamo" in sys.modules)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
