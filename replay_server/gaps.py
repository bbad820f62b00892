"""The seqs of one actor counted lost that may still arrive (``Gaps``): a worker's resend fills
them, and the items charged for them stop counting as lost. The core keeps one per actor with such
seqs (``ReplayCore.gaps``); checkpoints hold them as JSON (``to_json``, ``from_json``).

Room: replay_server (component). May import: the standard library; never another component.
"""

from __future__ import annotations

from typing import Any

#: Seqs counted lost that stay fillable, per actor: the newest this many (a worker holds at most
#: its MAX_IN_FLIGHT unacknowledged batches, 64, so older ones can never come).
MISSING_KEPT = 256


class Gaps:
    """One actor's seqs counted lost that may still arrive, with the items each gap was charged
    (from the actor's env steps). A batch that fills a seq takes its items off its gap's charge;
    the gap's last seq filled takes the rest, so a gap filled whole counts exactly 0 lost.

        >>> g = Gaps(); g.add(3, 6, 30)  # seqs 3, 4, 5: 30 items counted lost
        >>> g.fill(4, 10), g.fill(4, 10), g.missing
        (10, None, [3, 5])
        >>> g.fill(3, 10), g.fill(5, 8)
        (10, 10)
    """

    def __init__(self) -> None:
        self._seq_gap: dict[int, int] = {}  # missing seq -> its gap's first seq, ascending
        self._gap: dict[int, list[int]] = {}  # gap's first seq -> [items still charged, seqs still tracked]

    @property
    def missing(self) -> list[int]:
        return list(self._seq_gap)

    def add(self, first: int, end: int, charged: int) -> None:
        """Seqs ``first .. end - 1`` were skipped, ``charged`` items counted lost for them."""
        tracked = range(max(first, end - MISSING_KEPT), end)
        if not tracked:
            return
        self._gap[first] = [charged, len(tracked)]
        for s in tracked:
            self._seq_gap[s] = first
        while len(self._seq_gap) > MISSING_KEPT:  # the oldest stay lost for good
            s = next(iter(self._seq_gap))
            self._forget(s, self._seq_gap.pop(s))

    def fill(self, seq: int, n: int) -> int | None:
        """``seq`` arrived with ``n`` items: the items no longer lost, or None if it is not missing."""
        first = self._seq_gap.pop(seq, None)
        if first is None:
            return None
        gap = self._gap[first]
        gap[1] -= 1
        released = gap[0] if gap[1] == 0 else min(n, gap[0])
        gap[0] -= released
        if gap[1] == 0:
            del self._gap[first]
        return released

    def _forget(self, seq: int, first: int) -> None:
        gap = self._gap[first]
        gap[1] -= 1
        if gap[1] == 0:
            del self._gap[first]

    def to_json(self) -> dict[str, Any]:
        return {"missing": [[s, f] for s, f in self._seq_gap.items()],
                "gaps": [[f, c, t] for f, (c, t) in self._gap.items()]}

    @classmethod
    def from_json(cls, body: dict[str, Any]) -> "Gaps":
        g = cls()
        g._gap = {int(f): [int(c), int(t)] for f, c, t in body.get("gaps", [])}
        g._seq_gap = {int(s): int(f) for s, f in sorted(body.get("missing", [])) if int(f) in g._gap}
        return g
