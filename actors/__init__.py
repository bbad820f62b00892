"""laneshift.actors: env workers and the lane-change environments.

Importing this package registers the gymnasium ids (``laneshift/StraightLaneChange-v0``, ...),
so ``gym.make("laneshift.actors:laneshift/StraightLaneChange-v0")`` works in fresh processes.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from . import envs  # noqa: F401  (registers the environments)
