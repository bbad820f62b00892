"""laneshift.actors: env workers and the lane-change environments.

Importing this package registers the gymnasium ids (``laneshift/StraightLaneChange-v0``, ...),
so ``gym.make("laneshift.actors:laneshift/StraightLaneChange-v0")`` works in fresh processes.
"""

from . import envs  # noqa: F401  (registers the environments)
