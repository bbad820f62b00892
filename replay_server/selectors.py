"""How a replay table picks the rows of a sample (Reverb's ``Table(sampler, ...)`` strategy
objects): ``UniformSelector`` or ``PrioritizedSelector`` (Schaul et al. 2016: a sum tree over
[demo rows | online rows], new items at the highest priority seen, importance weights). The core
calls the same five methods whichever it holds, under its lock:

- ``draw(rng, rows, n_demo, online_tail, online_size, online_capacity)`` -> ``Draw``;
- ``stored(online, tail_before, keys)``: an insert into the online table (which items came,
  which went: from ``tail_before`` to its tail); the uniform selector ignores it, so the ingest
  path computes no rows for it;
- ``demos_off()``: the demo rows leave what is sampled (rehearsal's phase 2);
- ``update(demo_index, demo_priority, online_rows, online_priority)``: new raw priorities;
- ``priority_of(leaves)``: the sampling mass of leaves (inspection).

    >>> import numpy as np
    >>> s = UniformSelector()
    >>> d = s.draw(np.random.default_rng(0), 4, n_demo=2, online_tail=0, online_size=3, online_capacity=8)
    >>> d.is_demo.shape, float(d.weight.max())
    ((4,), 1.0)

Room: replay_server (component). May import: numpy and this package's sum tree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .sum_tree import SumTree


@dataclass(frozen=True)
class Draw:
    """Rows drawn for one sample: which are demo rows, their rows in each table, the importance
    weight of each drawn row (all ones for uniform sampling)."""

    is_demo: np.ndarray  # bool (rows,)
    demo_rows: np.ndarray  # rows of the demo table
    online_rows: np.ndarray  # rows of the online ring
    weight: np.ndarray  # float32 (rows,)
    # What a learner sampling several shards needs to turn each shard's weights into the weights
    # of one draw over all of them (learner/shards.py): the largest (N P(i))^-beta before the
    # normalisation, and the total priority mass sampled over (both 1 / 0 for uniform sampling).
    scale: float = 1.0
    mass: float = 0.0


class UniformSelector:
    """Every live item equally likely: the demo region (when sampled) and the online items in
    the ring from its tail on."""

    prioritized = False

    def __init__(self) -> None:
        # Per batch size: all-False is_demo and all-ones weights, shared by every draw of that size
        # and read-only (a sample of 256 rows made these two arrays anew for 3 us of its ~140).
        self._constants: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def draw(self, rng: np.random.Generator, rows: int, n_demo: int, online_tail: int, online_size: int,
             online_capacity: int) -> Draw:
        pick = rng.integers(0, n_demo + online_size, size=rows)
        if n_demo == 0:  # online rows only (no demos sampled): skip the masks
            no_demo, ones = self._constants.get(rows) or self._constant(rows)
            start = online_tail % online_capacity
            # The live rows are start .. start + size - 1, modulo the capacity: all rows when the
            # ring is full, 0 .. size - 1 until it first wraps. Either way no modulo is needed.
            online = pick if start == 0 or online_size == online_capacity else (start + pick) % online_capacity
            return Draw(no_demo, pick[:0], online, ones)
        is_demo = pick < n_demo
        online_rows = (online_tail + pick[~is_demo] - n_demo) % online_capacity
        return Draw(is_demo, pick[is_demo], online_rows, np.ones(rows, np.float32))

    def _constant(self, rows: int) -> tuple[np.ndarray, np.ndarray]:
        no_demo, ones = np.zeros(rows, bool), np.ones(rows, np.float32)
        no_demo.flags.writeable = ones.flags.writeable = False
        if len(self._constants) < 64:  # a few batch sizes in practice; bounded whatever is asked
            self._constants[rows] = (no_demo, ones)
        return no_demo, ones

    def stored(self, online: Any, tail_before: int, keys: np.ndarray) -> None:
        pass

    def demos_off(self) -> None:
        pass

    def update(self, demo_index: np.ndarray, demo_priority: np.ndarray, online_rows: np.ndarray,
               online_priority: np.ndarray) -> int:
        return 0

    def priority_of(self, leaves: np.ndarray) -> np.ndarray | None:
        return None


class PrioritizedSelector:
    """P(i) ~ p_i ** alpha over one sum tree of ``demo_size + online_capacity`` leaves; demo
    leaves start at ``(1 + demo_bonus) ** alpha`` (``none`` has no demo rows at all)."""

    prioritized = True

    def __init__(self, demo_size: int, online_capacity: int, alpha: float, beta: float, demo_bonus: float):
        self.demo_size, self.alpha, self.beta = demo_size, alpha, beta
        self.tree = SumTree(demo_size + online_capacity)
        self.max_priority = 1.0
        if demo_size:
            self.tree.set(np.arange(demo_size), np.full(demo_size, (1.0 + demo_bonus) ** alpha))

    def draw(self, rng: np.random.Generator, rows: int, n_demo: int, online_tail: int, online_size: int,
             online_capacity: int) -> Draw:
        leaves = self.tree.sample(rng, rows)
        is_demo = leaves < self.demo_size
        # Importance weights (N P(i))^-beta, normalised by the batch maximum.
        prob = self.tree.get(leaves) / self.tree.total
        weight = (float(n_demo + online_size) * prob) ** -self.beta
        scale = float(weight.max())
        return Draw(is_demo, leaves[is_demo], leaves[~is_demo] - self.demo_size,
                    (weight / scale).astype(np.float32), scale, float(self.tree.total))

    def stored(self, online: Any, tail_before: int, keys: np.ndarray) -> None:
        if online.tail > tail_before:  # items gone (frame tables: maybe not overwritten yet)
            self.dropped(np.arange(tail_before, online.tail) % online.capacity)
        self.inserted(online.rows_of(keys))

    def inserted(self, online_rows: np.ndarray) -> None:
        # New items get the highest priority seen: each is sampled at least once soon.
        self.tree.set(self.demo_size + online_rows, np.full(len(online_rows), self.max_priority ** self.alpha))

    def dropped(self, online_rows: np.ndarray) -> None:
        self.tree.set(self.demo_size + online_rows, np.zeros(len(online_rows)))

    def demos_off(self) -> None:
        if self.demo_size:
            self.tree.set(np.arange(self.demo_size), np.zeros(self.demo_size))

    def update(self, demo_index: np.ndarray, demo_priority: np.ndarray, online_rows: np.ndarray,
               online_priority: np.ndarray) -> int:
        leaves = np.concatenate([demo_index, self.demo_size + online_rows])
        values = np.concatenate([demo_priority, online_priority])
        if len(leaves):
            self.max_priority = max(self.max_priority, float(values.max()))
            self.tree.set(leaves, values ** self.alpha)
        return len(leaves)

    def priority_of(self, leaves: np.ndarray) -> np.ndarray:
        return np.asarray(self.tree.get(leaves), np.float64).copy()
