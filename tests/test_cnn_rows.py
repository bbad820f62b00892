"""learner.cnn_rows: the CNN looks at a window of each frame's rows (the straight road's band) while
the observation stays whole on the wire and in the replay. The window's Q-values ignore the rows
outside it and equal the same layers on the cropped frames; the network is named with its window
(learner.network_cnn), so a worker and a checkpoint's evaluation build the same one; the learner
trains it; bad windows are refused with the option's name.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from laneshift.actors.evaluation import load_checkpoint_policy
from laneshift.config import ConfigError, LearnerConfig, load_run_config
from laneshift.learner.dqn import DoubleDQN
from laneshift.qnet import build_q_network
from laneshift.wire import safetensors_dumps

torch.set_num_threads(1)
FRAMES = (4, 100, 100)


def _frames(n: int, seed: int) -> torch.Tensor:
    return torch.randint(0, 256, (n, *FRAMES), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("cnn", ["small", "nature"])
def test_the_window_sees_only_its_rows_and_is_the_cnn_on_the_cropped_frames(cnn):
    torch.manual_seed(0)
    windowed = build_q_network(FRAMES, 9, cnn=f"{cnn}[26:74]")
    frames = _frames(6, 1)
    other = frames.clone()
    other[:, :, :26] = 255 - other[:, :, :26]
    other[:, :, 74:] = 0
    torch.testing.assert_close(windowed(frames), windowed(other), rtol=0, atol=0)
    torch.manual_seed(0)
    cropped = build_q_network((4, 48, 100), 9, cnn=cnn)  # the same layers on 48-row frames
    cropped.load_state_dict(windowed.state_dict())
    torch.testing.assert_close(windowed(frames), cropped(frames[:, :, 26:74].contiguous()))
    whole = build_q_network(FRAMES, 9, cnn=cnn)
    assert sum(p.numel() for p in windowed.parameters()) < sum(p.numel() for p in whole.parameters())


def test_the_run_config_names_the_network_with_its_window():
    assert LearnerConfig(cnn="small").network_cnn == "small"
    assert LearnerConfig(cnn="small", cnn_rows="26:74").network_cnn == "small[26:74]"
    cfg = load_run_config(overrides={"env.observation": "grayscale", "learner.cnn": "small",
                                     "learner.cnn_rows": "26:74"})
    assert cfg.learner.network_cnn == "small[26:74]"
    for bad in ("74:26", "26", "a:b", "-1:40", "26:26"):
        with pytest.raises(ConfigError, match="learner.cnn_rows"):
            LearnerConfig(cnn="small", cnn_rows=bad)


@pytest.mark.parametrize("cnn, match", [("small[26:101]", "<= 100"), ("small[26:74", "FIRST:END"),
                                        ("small[40:50]", "too small"), ("tiny[26:74]", "no CNN")])
def test_a_window_the_frames_cannot_give_is_refused(cnn, match):
    with pytest.raises(ValueError, match=match):
        build_q_network(FRAMES, 9, cnn=cnn)


def test_the_learner_trains_the_window_and_a_checkpoint_rebuilds_it(tmp_path: Path):
    agent = DoubleDQN(FRAMES, 9, LearnerConfig(cnn="small", cnn_rows="26:74", batch_size=8, lr=1e-3,
                                               cnn_precision="bf16"))
    rng = np.random.default_rng(0)
    batch = dict(obs=rng.integers(0, 255, (8, *FRAMES), dtype=np.uint8),
                 next_obs=rng.integers(0, 255, (8, *FRAMES), dtype=np.uint8),
                 action=rng.integers(0, 9, 8).astype(np.int64), reward=np.ones(8, np.float32),
                 terminated=np.ones(8, np.uint8), steps=np.ones(8, np.uint8), weight=np.ones(8, np.float32))
    losses = [agent.update(batch)["loss"] for _ in range(5)]
    assert agent.online.rows == (26, 74) and all(np.isfinite(losses)) and losses[-1] < losses[0]
    # What the learner writes (learner/loop.py's metadata: "cnn" is learner.network_cnn) loads back.
    path = tmp_path / "final.safetensors"
    tensors = {k: v.detach().float().numpy() for k, v in agent.online.state_dict().items()}
    path.write_bytes(safetensors_dumps(tensors, {"obs_shape": "4,100,100", "obs_dtype": "|u1", "n_actions": "9",
                                                 "hidden": "256,256", "dueling": "0", "cnn": "small[26:74]"}))
    policy = load_checkpoint_policy(path)
    obs = rng.integers(0, 255, (3, *FRAMES), dtype=np.uint8)
    acting = build_q_network(FRAMES, 9, cnn="small[26:74]")  # float32, as a worker acts
    acting.load_state_dict(agent.online.state_dict())
    with torch.no_grad():
        expected = acting(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(policy.policy.q(obs), expected, rtol=1e-6, atol=1e-6)
