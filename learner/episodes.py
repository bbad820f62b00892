"""The env workers' episode records as the learner keeps them: running statistics over the last
100 episodes (return, length, crash and achievement rates, epsilon), each worker's env steps, and
the records that could not be read (counted and said once, never a silent loss). ``read_record``
decodes one as the links take it (``seams.EpisodeUpdate``: the record or the error).

Room: learner (component). May import: numpy, the contract (``laneshift.wire``); never another
component.
"""

from __future__ import annotations

import collections

import numpy as np

from laneshift import wire

#: How many of the newest episodes the running means cover.
WINDOW = 100


class EpisodeStats:
    """The episodes seen so far. ``count`` is kept with the learner's state across restarts."""

    def __init__(self, lane_change: bool, count: int = 0):
        self.lane_change = lane_change  # the LKA plant has no target lane: no achievement rate
        self.returns: collections.deque[float] = collections.deque(maxlen=WINDOW)
        self.lengths: collections.deque[float] = collections.deque(maxlen=WINDOW)
        self.crashes: collections.deque[float] = collections.deque(maxlen=WINDOW)
        self.achieved: collections.deque[float] = collections.deque(maxlen=WINDOW)
        self.count = count
        self.bad_records = 0  # episode records that failed wire.decode_episode
        self.worker_steps: dict[str, int] = {}
        self.worker_epsilon: dict[str, float] = {}  # each worker's epsilon at its newest episode

    def accept(self, update: wire.EpisodeRecord | wire.WireError) -> wire.EpisodeRecord | None:
        """One record as the links took it, or None (counted) if it could not be read."""
        if isinstance(update, wire.WireError):
            self.bad_records += 1
            if self.bad_records == 1:
                print(f"learner: skipped an unreadable episode record ({update}); "
                      f"the count is bad_episode_records in the status", flush=True)
            return None
        return update

    def add(self, ep: wire.EpisodeRecord) -> None:
        crashed = float(ep.crashed)
        self.count += 1
        self.returns.append(ep.return_)
        self.lengths.append(ep.length)
        self.crashes.append(crashed)
        self.achieved.append(float(ep.on_target_lane) * (1.0 - crashed))
        # A worker's count only grows (a restarted worker resumes from what the replay server stored).
        self.worker_steps[ep.actor] = max(self.worker_steps.get(ep.actor, 0), ep.env_steps)
        self.worker_epsilon[ep.actor] = ep.epsilon

    @property
    def env_steps(self) -> int:
        """The workers' env steps, as their newest episodes reported them."""
        return sum(self.worker_steps.values())

    def return_mean(self) -> float | None:
        return float(np.mean(self.returns)) if self.returns else None

    def length_mean(self) -> float | None:
        return float(np.mean(self.lengths)) if self.lengths else None

    def crash_rate(self) -> float | None:
        return float(np.mean(self.crashes)) if self.crashes else None

    def achievement_rate(self) -> float | None:
        return float(np.mean(self.achieved)) if self.achieved and self.lane_change else None

    def epsilon(self) -> float | None:
        """The workers' mean epsilon at their newest episodes."""
        return float(np.mean(list(self.worker_epsilon.values()))) if self.worker_epsilon else None


def read_record(payload: bytes) -> wire.EpisodeRecord | wire.WireError:
    """An episode record as sent, decoded; the WireError of one that cannot be read (the learner
    counts it: ``EpisodeStats.accept``)."""
    try:
        return wire.decode_episode(payload)
    except wire.WireError as exc:
        return exc
