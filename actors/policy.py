"""The actor's copy of the Q-network, acting epsilon-greedily.

    >>> import numpy as np
    >>> p = QPolicy((4,), 3, hidden=(8,), seed=0)
    >>> p.act(np.zeros((2, 4), np.float32), epsilon=0.0).shape
    (2,)
"""

from __future__ import annotations

import numpy as np
import torch

from laneshift import wire
from laneshift.learner.networks import build_q_network
from laneshift.learner.weights import load_into


class QPolicy:
    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, hidden: tuple[int, ...], seed: int = 0,
                 dueling: bool = False):
        self.net = build_q_network(obs_shape, n_actions, hidden, dueling).eval()
        self.n_actions = n_actions
        self.rng = np.random.default_rng(seed)
        self.version = -1
        self.phase = 0

    def load(self, weights: wire.Weights) -> None:
        load_into(self.net, weights.tensors)
        self.version, self.phase = weights.version, weights.phase

    @torch.no_grad()
    def greedy(self, obs: np.ndarray) -> np.ndarray:
        return self.net(torch.as_tensor(obs)).argmax(dim=1).numpy()

    def act(self, obs: np.ndarray, epsilon: float) -> np.ndarray:
        actions = self.greedy(obs)
        explore = self.rng.random(len(actions)) < epsilon
        actions[explore] = self.rng.integers(0, self.n_actions, size=int(explore.sum()))
        return actions
