"""learner.cnn_precision and learner.mlp_precision: the convolutions (an MLP's hidden layers) in
bfloat16 give the float32 network's Q-values to bfloat16's resolution, keep float32 parameters,
state-dict names and Q-values, train, and leave the other kind of network and acting alone.
CPU, SmallCNN and small MLPs, no sleeps.

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


def test_an_mlp_ignores_the_conv_precision_and_a_cnn_the_mlp_precision():
    net = build_q_network((6,), 3, (8,), conv_precision="bf16")
    assert not hasattr(net, "conv_dtype") and net.trunk_dtype is None
    cnn = build_q_network((4, 100, 100), 9, cnn="small", mlp_precision="bf16")
    assert cnn.conv_dtype is None and not hasattr(cnn, "trunk_dtype")


@pytest.mark.parametrize("heads", [1, 4])
def test_bf16_hidden_layers_give_the_fp32_q_values_to_bf16_resolution(heads):
    torch.manual_seed(0)
    fp32 = build_q_network((96,), 9, (512, 512), dueling=True, heads=heads)
    bf16 = build_q_network((96,), 9, (512, 512), dueling=True, heads=heads, mlp_precision="bf16")
    assert list(bf16.state_dict()) == list(fp32.state_dict()), "published checkpoints would not load"
    bf16.load_state_dict(fp32.state_dict())
    obs = torch.randn(64, 96, generator=torch.Generator().manual_seed(1))
    obs[:, -4:] = torch.nn.functional.one_hot(torch.arange(64) % 4, 4).float()  # the road's one-hot
    exact, approx = fp32(obs), bf16(obs)
    assert approx.dtype == torch.float32 and all(p.dtype == torch.float32 for p in bf16.parameters())
    assert not torch.equal(exact, approx), "the bf16 network computed in float32"
    assert torch.allclose(exact, approx, atol=0.02, rtol=0.02)
    with pytest.raises(ValueError, match="MLP precision"):
        build_q_network((96,), 9, mlp_precision="fp16")
    with pytest.raises(ConfigError, match="learner.mlp_precision"):
        LearnerConfig(mlp_precision="int8")


def test_the_learner_trains_its_bf16_hidden_layers_and_acts_in_fp32():
    agent = DoubleDQN((12,), 9, LearnerConfig(hidden=(32, 32), batch_size=16, mlp_precision="bf16", lr=1e-3,
                                              dueling=True))
    rng = np.random.default_rng(0)
    batch = dict(obs=rng.standard_normal((16, 12), dtype=np.float32),
                 next_obs=rng.standard_normal((16, 12), dtype=np.float32),
                 action=rng.integers(0, 9, 16).astype(np.int64), reward=np.ones(16, np.float32),
                 terminated=np.ones(16, np.uint8), steps=np.ones(16, np.uint8), weight=np.ones(16, np.float32))
    first = agent.online.net[0].weight.detach().clone()
    losses = [agent.update(batch)["loss"] for _ in range(10)]
    assert agent.online.trunk_dtype == torch.bfloat16 and agent.target.trunk_dtype == torch.bfloat16
    assert not torch.equal(first, agent.online.net[0].weight), "the hidden layers did not learn"
    assert all(np.isfinite(losses)) and losses[-1] < losses[0]
    acting = build_q_network((12,), 9, (32, 32), dueling=True)  # what a worker builds: no precision given
    acting.load_state_dict(agent.online.state_dict())
    assert acting.trunk_dtype is None


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


@pytest.mark.parametrize("cnn", ["small", "nature"])
def test_the_folded_scale_gives_the_q_values_of_frames_divided_by_255(cnn):
    # on the CPU forward folds 1/255 into the first convolution's weights (frames cast once, no division):
    # the same function as the layers applied to frames / 255, in float32 to float32's rounding.
    torch.manual_seed(0)
    net = build_q_network((4, 100, 100), 9, cnn=cnn)
    frames = torch.randint(0, 256, (8, 4, 100, 100), dtype=torch.uint8, generator=torch.Generator().manual_seed(2))
    reference = net.head(net.features(frames.float() / 255.0))
    torch.testing.assert_close(net(frames), reference, rtol=1e-5, atol=1e-6)  # forward folds on the CPU
    torch.testing.assert_close(net.scaled_features(frames, fold=False), net.features(frames.float() / 255.0))
    net(frames).sum().backward()  # the gradient reaches the stored (unscaled) weights
    assert net.features[0].weight.grad is not None and net.features[0].weight.grad.abs().sum() > 0
