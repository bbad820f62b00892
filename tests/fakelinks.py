"""A test double of the learner's links (``laneshift.learner.seams.LearnerLinks``) for in-process
tests of the Learner loop: every call that would reach the replay server, the actors or the router
succeeds and does nothing. Tests subclass it with the sampling and the reports they need.

Room: tests, helper (tests/ is not a package: test modules load it by path). May import: the contract.
"""

from __future__ import annotations

from laneshift import wire


class QuietLinks:
    """Links whose control calls all succeed silently: no phase switch refused, no stop asked."""

    def __init__(self) -> None:
        self.status: dict = {}

    def set_phase(self, phase: int) -> bool:
        return True

    def publish_weights(self, weights: wire.Weights) -> None:
        pass

    def send_priorities(self, update: wire.PriorityUpdate) -> None:
        pass

    def publish_stats(self, status, final: bool = False) -> None:
        self.status = status.stats_message(final)

    def take_episodes(self) -> list:
        return []

    def stop_requested(self) -> bool:
        return False

    def stop_all(self) -> None:
        pass
