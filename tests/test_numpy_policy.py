"""The env worker's numpy MLP computes what the learner's torch MLP computes, for plain and
dueling heads, and an env worker for vector observations never imports torch.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from laneshift import wire
from laneshift.actors.policy import NumpyMLP, QPolicy
from laneshift.qnet import build_q_network
from laneshift.qnet import to_wire


@pytest.mark.parametrize("hidden,dueling", [((256, 256), False), ((64,), True), ((32, 16, 8), False), ((), True)])
def test_numpy_mlp_matches_the_torch_network(hidden, dueling):
    torch.manual_seed(0)
    net = build_q_network((82,), 9, hidden, dueling)
    tensors = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    mlp = NumpyMLP(82, 9, hidden, dueling)
    mlp.load(tensors)
    obs = np.random.default_rng(1).normal(size=(64, 82)).astype(np.float32)
    with torch.no_grad():
        expected = net(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(mlp(obs), expected, rtol=1e-5, atol=1e-5)
    assert (mlp(obs).argmax(1) == expected.argmax(1)).all()


@pytest.mark.parametrize("dueling", [False, True])
def test_one_head_per_road_each_row_reads_the_head_its_one_hot_names(dueling):
    torch.manual_seed(0)
    net = build_q_network((86,), 9, (32,), dueling, heads=4)
    tensors = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    mlp = NumpyMLP(86, 9, (32,), dueling, heads=4)
    mlp.load(tensors)
    rng = np.random.default_rng(2)
    obs = rng.normal(size=(40, 86)).astype(np.float32)
    roads = rng.integers(0, 4, size=40)
    obs[:, -4:] = np.eye(4, dtype=np.float32)[roads]
    with torch.no_grad():
        expected = net(torch.from_numpy(obs)).numpy()
        # Each head by hand: the trunk, then the head's own rows of the last layer.
        h = net.net[:-1](torch.from_numpy(obs)).numpy()
    head = net.net[-1]
    for row, road in zip(range(40), roads):
        if dueling:
            adv = h[row] @ tensors["net.2.advantage.weight"][9 * road:9 * road + 9].T \
                + tensors["net.2.advantage.bias"][9 * road:9 * road + 9]
            q = h[row] @ tensors["net.2.value.weight"][road] + tensors["net.2.value.bias"][road] + adv - adv.mean()
        else:
            q = h[row] @ tensors["net.2.weight"][9 * road:9 * road + 9].T + tensors["net.2.bias"][9 * road:9 * road + 9]
        np.testing.assert_allclose(expected[row], q, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(mlp(obs), expected, rtol=1e-5, atol=1e-5)
    assert getattr(head, "heads", 4) == 4
    # Another road's one-hot on the same features gives that road's head: the heads differ.
    swapped = obs.copy()
    swapped[:, -4:] = np.eye(4, dtype=np.float32)[(roads + 1) % 4]
    assert not np.allclose(mlp(swapped), expected)
    # A one-head policy cannot load a four-head network's weights (and the other way round).
    with pytest.raises(ValueError):
        NumpyMLP(86, 9, (32,), dueling).load(tensors)


def test_a_frame_network_has_no_heads_per_road():
    with pytest.raises(ValueError, match="vector observation"):
        build_q_network((4, 84, 84), 9, heads=4)
    with pytest.raises(ValueError, match="vector observation"):
        QPolicy((4, 84, 84), 9, (), heads=4)


def test_policy_loads_the_learners_weights_and_refuses_another_network():
    torch.manual_seed(0)
    net = build_q_network((82,), 9, (64, 64), False)
    p = QPolicy((82,), 9, (64, 64))
    p.load(wire.decode_weights(to_wire(net, 3, 2, 10)))
    assert (p.version, p.phase) == (3, 2)
    with pytest.raises(ValueError):
        p.load(wire.decode_weights(to_wire(build_q_network((82,), 9, (32,), False), 4, 2, 10)))
    assert p.version == 3  # the refused weights changed nothing


def test_an_env_worker_for_vector_observations_does_not_import_torch():
    code = ("import sys\n"
            "from laneshift.config import load_run_config\n"
            "from laneshift.deploy.builder import Builder\n"
            "cfg = load_run_config(overrides={'env.scenario': 'lka', 'actor.workers': 1})\n"
            "w = Builder(cfg).env_worker(0)\n"
            "w.policy.act(w.envs[0].reset(seed=0)[0][None], 0.5)\n"
            "print('torch' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
