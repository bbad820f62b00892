"""Reverb-style rate limiting between the actors' inserts and the learner's samples.

``SampleToInsertRatio`` keeps ``samples ~= samples_per_insert * (inserts - min_size)`` within
``tolerance`` sampled rows, like Reverb's ``SampleToInsertRatio(error_buffer=...)``:

- the learner may sample while ``samples + rows <= ratio * inserts' + tolerance``;
- actors may insert while ``ratio * inserts' - samples <= tolerance`` (the learner is not too
  far behind); the replay server broadcasts this on ``.../replay/flow`` and actors wait on it.

So the update-to-data ratio is a setting, not an accident of relative speeds. Before
``min_size`` items exist, inserts are always allowed and sampling never. A request of more rows
than ``tolerance`` could block both sides forever: such configurations are refused.

    >>> rl = SampleToInsertRatio(samples_per_insert=8.0, min_size=100, capacity=1000, tolerance=512)
    >>> rl.can_sample(size=50, inserts=50, samples=0, rows=256)
    False
    >>> rl.can_insert(inserts=300, samples=0)   # 200 * 8 = 1600 rows owed to the learner > 512
    False

Room: replay_server (component). May import: the contract and laneshift.replay_server; never another
component.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SampleToInsertRatio:
    samples_per_insert: float  # 0 = no ratio: only the minimum size applies, inserts never wait
    min_size: int
    capacity: int  # online items the table can hold
    tolerance: float = 0.0  # rows of slack on either side of the ratio

    def __post_init__(self) -> None:
        if self.min_size > self.capacity:
            raise ValueError(f"replay.min_size {self.min_size} exceeds the online table's capacity "
                             f"{self.capacity}: sampling would wait forever")
        if self.samples_per_insert < 0 or self.tolerance < 0:
            raise ValueError("samples_per_insert and tolerance must be >= 0")

    def _owed(self, inserts: int, samples: int) -> float:
        """Rows the learner may still sample (negative: it sampled ahead of the ratio)."""
        return max(0, inserts - self.min_size) * self.samples_per_insert - samples

    def can_sample(self, *, size: int, inserts: int, samples: int, rows: int) -> bool:
        if size < self.min_size:
            return False
        if self.samples_per_insert == 0:
            return True
        return rows <= self._owed(inserts, samples) + self.tolerance

    def can_insert(self, *, inserts: int, samples: int) -> bool:
        if self.samples_per_insert == 0 or inserts < self.min_size:
            return True
        return self._owed(inserts, samples) <= self.tolerance

    def check_request(self, rows: int) -> None:
        """A request larger than the tolerance could block sampling and inserting at once."""
        if self.samples_per_insert and rows > self.tolerance:
            raise ValueError(f"a request of {rows} rows exceeds the rate limiter's tolerance {self.tolerance:.0f}: "
                             "sampling and inserting could block each other")

    def state(self, *, size: int, inserts: int, samples: int) -> dict:
        return {"min_size": self.min_size, "samples_per_insert": self.samples_per_insert,
                "tolerance": self.tolerance, "size_ok": size >= self.min_size,
                "rows_owed_to_learner": None if self.samples_per_insert == 0 else self._owed(inserts, samples),
                "insert_ok": self.can_insert(inserts=inserts, samples=samples)}
