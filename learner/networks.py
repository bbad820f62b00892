"""Q-networks: an MLP for vector observations, the Nature CNN for stacked grayscale frames.

    >>> net = build_q_network((25,), 9, hidden=(64, 64))
    >>> tuple(net(torch.zeros(2, 25)).shape)
    (2, 9)
"""

from __future__ import annotations

import torch
from torch import nn


class MLPQNetwork(nn.Module):
    def __init__(self, obs_dim: int, n_actions: int, hidden: tuple[int, ...] = (256, 256)):
        super().__init__()
        layers: list[nn.Module] = []
        size = obs_dim
        for h in hidden:
            layers += [nn.Linear(size, h), nn.ReLU()]
            size = h
        layers.append(nn.Linear(size, n_actions))
        self.net = nn.Sequential(*layers)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs.float())


class NatureCNN(nn.Module):
    """Mnih et al. 2015 on uint8 frames (C, H, W); scales to [0, 1] inside."""

    def __init__(self, in_shape: tuple[int, int, int], n_actions: int):
        super().__init__()
        c = in_shape[0]
        self.features = nn.Sequential(
            nn.Conv2d(c, 32, 8, stride=4), nn.ReLU(),
            nn.Conv2d(32, 64, 4, stride=2), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1), nn.ReLU(), nn.Flatten())
        with torch.no_grad():
            flat = self.features(torch.zeros(1, *in_shape)).shape[1]
        self.head = nn.Sequential(nn.Linear(flat, 512), nn.ReLU(), nn.Linear(512, n_actions))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(obs.float() / 255.0))


def build_q_network(obs_shape: tuple[int, ...], n_actions: int, hidden: tuple[int, ...] = (256, 256)) -> nn.Module:
    """MLP for 1-D observations, Nature CNN for (stack, H, W) images."""
    if len(obs_shape) == 1:
        return MLPQNetwork(obs_shape[0], n_actions, hidden)
    if len(obs_shape) == 3:
        return NatureCNN(tuple(obs_shape), n_actions)  # type: ignore[arg-type]
    raise ValueError(f"no Q-network for observation shape {obs_shape}")
