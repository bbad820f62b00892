"""What a run's environment looks like on the wire: the env's id, its transition schema
(observation shape and dtype, action count) and the env kwargs it was computed for.

Contract floor: computed once by whoever launches the run (``laneshift.actors.envs.spec_of``
builds the env and reads its spaces) and handed to the components as an ``EnvSpec``, or as the
plain dict of ``spec_to_dict`` across a process boundary; no process that does not run the
simulator builds one just to learn the observation's shape. Room: the contract (shared by every process). May import: ``laneshift.config``,
``laneshift.wire``.

    >>> from laneshift.config import EnvConfig
    >>> from laneshift.wire import TransitionSchema
    >>> cfg = EnvConfig(scenario="lka")
    >>> spec = EnvSpec("laneshift/LaneKeepingAssist-v0", TransitionSchema((6,), "<f4", 31), tuple(sorted(cfg.env_kwargs().items())))
    >>> spec_from_dict(spec_to_dict(spec), cfg) == spec
    True
"""

from __future__ import annotations

from dataclasses import dataclass

from .config import EnvConfig
from .config.sections import ROADS
from .wire import TransitionSchema


#: The env options a network was trained with that an evaluation must repeat (EnvConfig fields of the
#: same names): those that change the vector observation's layout, how the frames are drawn and spaced, and the
#: shield and its figures, which change what an action does. A learner checkpoint's metadata carries
#: those the run set, so an evaluation can build the same env.
RECORDED_ENV_OPTIONS = ("lane_features", "alongside_features", "gap_features", "shield", "shield_gap",
                        "shield_decel", "frame_supersample", "frame_interval",
                        "frame_centering", "frame_scale")

#: Scenario name -> gymnasium id (registered by importing ``laneshift.actors.envs``).
SCENARIOS: dict[str, str] = {
    "straight": "laneshift/StraightLaneChange-v0",
    "merge": "laneshift/MergeLaneChange-v0",
    "curve": "laneshift/CurveLaneChange-v0",
    "roundabout": "laneshift/RoundaboutLaneChange-v0",
    "allroads": "laneshift/AllRoadsLaneChange-v0",
    "lka": "laneshift/LaneKeepingAssist-v0",
}

#: The roads of scenario ``allroads`` (one network for all four), in the order of the one-hot its
#: vector observation ends with; an episode reset with seed s drives ``ALLROADS[s % 4]``.
ALLROADS: tuple[str, ...] = ROADS  # one tuple: the config checks env.road and learner.heads against it


@dataclass(frozen=True)
class EnvSpec:
    env_id: str
    schema: TransitionSchema
    env_kwargs: tuple[tuple[str, object], ...]


def spec_to_dict(spec: EnvSpec) -> dict:
    return {"env_id": spec.env_id, "obs_shape": list(spec.schema.obs_shape), "obs_dtype": spec.schema.obs_dtype,
            "n_actions": spec.schema.n_actions, "env_kwargs": [list(kv) for kv in spec.env_kwargs]}


def spec_from_dict(plain: dict, cfg: EnvConfig) -> EnvSpec:
    """``spec_to_dict``'s output back as ``cfg``'s spec; it must be the spec of this very config
    (same env kwargs), else ValueError."""
    spec = EnvSpec(str(plain["env_id"]), TransitionSchema(tuple(int(d) for d in plain["obs_shape"]),
                                                          str(plain["obs_dtype"]), int(plain["n_actions"])),
                   tuple((str(k), v) for k, v in plain["env_kwargs"]))
    if spec.env_kwargs != tuple(sorted(cfg.env_kwargs().items())):
        raise ValueError(f"env spec for {cfg.scenario}: it was computed for other env settings")
    return spec
