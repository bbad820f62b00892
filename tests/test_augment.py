"""The learner's image augmentation (learner.augment=shift, DrQ's random shift): each row moves by
its own offset within the pad, edges repeated, the frames of a row together; the update uses it on
frames only and repeats for a seed. CPU, small frames, no sleeps.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from laneshift.config import ConfigError, LearnerConfig
from laneshift.learner.augment import random_shift
from laneshift.learner.dqn import DoubleDQN

torch.set_num_threads(1)


def _shifted_by_formula(frames: torch.Tensor, dy: int, dx: int) -> torch.Tensor:
    """One row [channels, h, w] shifted the slow way: out[:, i, j] = frames[:, clamp(i + dy), clamp(j + dx)]."""
    _, h, w = frames.shape
    out = torch.empty_like(frames)
    for i in range(h):
        for j in range(w):
            out[:, i, j] = frames[:, min(max(i + dy, 0), h - 1), min(max(j + dx, 0), w - 1)]
    return out


def test_each_row_is_its_frames_shifted_within_the_pad_with_edges_repeated():
    pad = 2
    frames = torch.randint(0, 255, (12, 3, 9, 11), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    out = random_shift(frames, pad, torch.Generator().manual_seed(7))
    assert out.shape == frames.shape and out.dtype == torch.uint8
    offsets = set()
    for row in range(frames.shape[0]):
        matches = [(dy, dx) for dy in range(-pad, pad + 1) for dx in range(-pad, pad + 1)
                   if torch.equal(out[row], _shifted_by_formula(frames[row], dy, dx))]
        assert matches, f"row {row} is no shift of its frames within {pad} pixels"
        offsets.add(matches[0])
    assert len(offsets) > 3, "the rows did not get offsets of their own"


def test_the_offsets_repeat_for_a_seed_and_differ_between_seeds():
    frames = torch.randint(0, 255, (16, 4, 20, 20), dtype=torch.uint8, generator=torch.Generator().manual_seed(2))
    a = random_shift(frames, 4, torch.Generator().manual_seed(3))
    assert torch.equal(a, random_shift(frames, 4, torch.Generator().manual_seed(3)))
    assert not torch.equal(a, random_shift(frames, 4, torch.Generator().manual_seed(4)))


def test_a_batch_that_is_not_frames_is_refused():
    with pytest.raises(ValueError, match="batch, channels, height, width"):
        random_shift(torch.zeros(4, 8), 2)


def _frame_batch(rows: int = 8) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return dict(obs=rng.integers(0, 255, (rows, 4, 100, 100), dtype=np.uint8),
                next_obs=rng.integers(0, 255, (rows, 4, 100, 100), dtype=np.uint8),
                action=rng.integers(0, 9, rows).astype(np.int64), reward=rng.normal(size=rows).astype(np.float32),
                terminated=np.zeros(rows, np.uint8), steps=np.ones(rows, np.uint8), weight=np.ones(rows, np.float32))


def _loss_after_two_updates(augment: str, seed: int = 0) -> float:
    agent = DoubleDQN((4, 100, 100), 9, LearnerConfig(cnn="small", batch_size=8, augment=augment, seed=seed))
    batch = _frame_batch()
    agent.update(batch)
    return agent.update(batch)["loss"]


def test_the_update_shifts_frames_repeatably_and_only_when_asked():
    shifted = _loss_after_two_updates("shift")
    assert shifted == _loss_after_two_updates("shift")  # the learner's own generator: same seed, same shifts
    assert shifted != _loss_after_two_updates("none")  # the network saw other pixels


def test_vector_observations_are_never_shifted():
    cfg = LearnerConfig(hidden=(16,), batch_size=8, augment="shift")
    plain = LearnerConfig(hidden=(16,), batch_size=8)
    rng = np.random.default_rng(0)
    batch = dict(obs=rng.normal(size=(8, 6)).astype(np.float32), next_obs=rng.normal(size=(8, 6)).astype(np.float32),
                 action=np.zeros(8, np.int64), reward=np.ones(8, np.float32), terminated=np.zeros(8, np.uint8),
                 steps=np.ones(8, np.uint8), weight=np.ones(8, np.float32))
    assert DoubleDQN((6,), 3, cfg).update(batch)["loss"] == DoubleDQN((6,), 3, plain).update(batch)["loss"]


@pytest.mark.parametrize("pad", [0, 33])
def test_a_pad_out_of_range_is_refused(pad):
    with pytest.raises(ConfigError, match="learner.augment_pad"):
        LearnerConfig(augment="shift", augment_pad=pad)
