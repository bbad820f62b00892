"""Episode outcomes: the paper's survival (no collision) and achievement (on the target lane).

Both are read from the episode's final ``info`` dict: ``info["crashed"]`` (highway-env's flag,
which laneshift's envs also set when the car leaves the road) and ``info["on_target_lane"]``.
As in the paper (and ``laneshift.tools.studies.evaluate``), an episode achieves only if it is on the target
lane at its last step *without* having crashed: a crash on the target lane is no achievement.
A missing key gives None ("unknown"), and a rate over episodes is None unless every episode
knows it.

Imports: numpy only.

Example::

    >>> outcome_rates([episode_outcome({"crashed": False, "on_target_lane": True}),
    ...                episode_outcome({"crashed": True, "on_target_lane": True})])
    {'survival_rate': 0.5, 'achievement_rate': 0.5}

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

# Info keys read from an episode's final info dict. Survival = no crash (the env reports a
# collision or leaving the road as "crashed"); achievement = on the target lane at the end.
CRASH_INFO_KEY = "crashed"
TARGET_LANE_INFO_KEY = "on_target_lane"


def episode_outcome(final_info: Mapping[str, Any] | None) -> dict[str, bool | None]:
    """``{"crashed": ..., "on_target_lane": ...}`` from an episode's last info (None = unknown)."""
    info = final_info or {}

    def flag(key: str) -> bool | None:
        value = info.get(key)
        return None if value is None else bool(value)

    return {"crashed": flag(CRASH_INFO_KEY), "on_target_lane": flag(TARGET_LANE_INFO_KEY)}


def outcome_rates(outcomes: Sequence[Mapping[str, bool | None]]) -> dict[str, float | None]:
    """Survival (no crash) and achievement (on target lane at the end) rates, None if unknown."""
    crashed = [o.get("crashed") for o in outcomes]
    on_target = [o.get("on_target_lane") for o in outcomes]
    survival = None
    achievement = None
    if outcomes and all(c is not None for c in crashed):
        survival = float(np.mean([not c for c in crashed]))
    if outcomes and all(t is not None for t in on_target):
        # A crashed episode never reaches the paper's step 300 on the target lane; with the
        # crash unknown (None) only the lane is known and counts.
        achievement = float(np.mean([bool(t) and not c for t, c in zip(on_target, crashed)]))
    return {"survival_rate": survival, "achievement_rate": achievement}
