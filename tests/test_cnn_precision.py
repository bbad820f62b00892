"""learner.cnn_precision: the convolutions in bfloat16 give the float32 network's Q-values to
bfloat16's resolution, keep float32 parameters and Q-values, train, and leave MLPs and acting alone.
CPU, SmallCNN, no sleeps.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from laneshift.config import ConfigError, LearnerConfig
from laneshift.learner.dqn import DoubleDQN
from laneshift.qnet import build_q_network

torch.set_num_threads(1)


def test_bf16_convolutions_give_the_fp32_q_values_to_bf16_resolution():
    torch.manual_seed(0)
    fp32 = build_q_network((4, 100, 100), 9, cnn="small")
    bf16 = build_q_network((4, 100, 100), 9, cnn="small", conv_precision="bf16")
    bf16.load_state_dict(fp32.state_dict())
    frames = torch.randint(0, 255, (16, 4, 100, 100), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    exact, approx = fp32(frames), bf16(frames)
    assert approx.dtype == torch.float32 and all(p.dtype == torch.float32 for p in bf16.parameters())
    assert not torch.equal(exact, approx), "the bf16 network computed in float32"
    assert torch.allclose(exact, approx, atol=0.02, rtol=0.02)
    assert (exact.argmax(1) == approx.argmax(1)).float().mean() >= 0.75


def test_an_unknown_precision_is_refused():
    with pytest.raises(ValueError, match="conv precision"):
        build_q_network((4, 100, 100), 9, cnn="small", conv_precision="fp8")
    with pytest.raises(ConfigError, match="learner.cnn_precision"):
        LearnerConfig(cnn_precision="fp16")


def test_an_mlp_ignores_the_precision():
    net = build_q_network((6,), 3, (8,), conv_precision="bf16")
    assert not hasattr(net, "conv_dtype")


def test_the_learner_trains_its_bf16_convolutions():
    agent = DoubleDQN((4, 100, 100), 9, LearnerConfig(cnn="small", batch_size=8, cnn_precision="bf16", lr=1e-3))
    rng = np.random.default_rng(0)
    batch = dict(obs=rng.integers(0, 255, (8, 4, 100, 100), dtype=np.uint8),
                 next_obs=rng.integers(0, 255, (8, 4, 100, 100), dtype=np.uint8),
                 action=rng.integers(0, 9, 8).astype(np.int64), reward=np.ones(8, np.float32),
                 terminated=np.ones(8, np.uint8), steps=np.ones(8, np.uint8), weight=np.ones(8, np.float32))
    conv = agent.online.features[0].weight.detach().clone()
    losses = [agent.update(batch)["loss"] for _ in range(5)]
    assert not torch.equal(conv, agent.online.features[0].weight), "the convolutions did not learn"
    assert all(np.isfinite(losses)) and losses[-1] < losses[0]
