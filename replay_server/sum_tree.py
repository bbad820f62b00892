"""A sum tree over leaf priorities with vectorised batch sampling and updates.

Prioritized experience replay (Schaul et al. 2016) samples item i with probability
``p_i / sum(p)``. The tree stores leaf masses in an array of size ``2 * L`` (``L`` a power of
two), node ``n``'s children at ``2n`` and ``2n + 1``, the root at 1. A batch is drawn with one
stratified prefix-sum search per level for the whole batch (numpy), and updates recompute only
the ancestors of changed leaves.

    >>> tree = SumTree(4)
    >>> tree.set(np.array([0, 3]), np.array([1.0, 3.0]))
    >>> tree.total
    4.0
    >>> sorted(set(tree.sample(np.random.default_rng(0), 100).tolist()))
    [0, 3]

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

import numpy as np


class SumTree:
    def __init__(self, size: int):
        self.size = int(size)
        self.leaves = 1 << max(0, (self.size - 1).bit_length())
        self.nodes = np.zeros(2 * self.leaves, np.float64)

    @property
    def total(self) -> float:
        return float(self.nodes[1])

    def get(self, index: np.ndarray) -> np.ndarray:
        return self.nodes[self.leaves + np.asarray(index)]

    def set(self, index: np.ndarray, value: np.ndarray) -> None:
        """Set leaf masses (>= 0, finite) and refresh their ancestors."""
        index = np.asarray(index, np.int64)
        value = np.asarray(value, np.float64)
        if index.size == 0:
            return
        if index.min() < 0 or index.max() >= self.size:
            raise IndexError(f"leaf index out of range [0, {self.size})")
        if not np.isfinite(value).all() or (value < 0).any():
            raise ValueError("priorities must be finite and >= 0")
        node = self.leaves + index
        self.nodes[node] = value  # with repeated indices the last value wins, as in a loop
        node = np.unique(node // 2)
        while node[0] >= 1:
            self.nodes[node] = self.nodes[2 * node] + self.nodes[2 * node + 1]
            if node[0] == 1:
                break
            node = np.unique(node // 2)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` leaf indices, drawn proportionally to mass with stratified uniforms."""
        total = self.total
        if total <= 0:
            raise ValueError("cannot sample from a tree with zero total mass")
        # One uniform per stratum: lower variance than n independent draws.
        u = (np.arange(n) + rng.random(n)) * (total / n)
        node = np.ones(n, np.int64)
        while node[0] < self.leaves:
            left = 2 * node
            left_mass = self.nodes[left]
            go_right = u >= left_mass
            u = np.where(go_right, u - left_mass, u)
            node = np.where(go_right, left + 1, left)
        leaf = node - self.leaves
        # Float round-off can land on a zero-mass leaf at the right edge: step back to a live one.
        dead = self.nodes[node] <= 0
        if dead.any():
            live = np.flatnonzero(self.nodes[self.leaves:self.leaves + self.size] > 0)
            leaf[dead] = live[np.minimum(np.searchsorted(live, leaf[dead]), len(live) - 1)]
        return leaf
