"""One flat, frozen dataclass per component, and the loader that builds them.

Each component receives only its own config. ``RunConfig`` just groups them so a run can be
saved and loaded as one YAML/TOML file with one section per component::

    env:     {scenario: straight, observation: vector}
    replay:  {capacity: 100000, demo_mode: rehearsal}
    learner: {lr: 0.0005}

A bad value is refused with a ``ConfigError`` naming the field, e.g.
``replay.demo_ratio: must be in (0, 1), got 1.5``.

    >>> cfg = load_run_config(overrides={"env.scenario": "lka", "actor.workers": "2"})
    >>> cfg.actor.workers
    2

One module per concern, each importing only those above it in this list (no circle):

- ``checks``: ``ConfigError``, ``NAME`` and the checks every section runs;
- ``sections``: the components' sections (``env``, ``actor``, ``replay``, ``learner``);
- ``run``: how a run is wired (``transport``, ``train``, ``deploy``) and ``RunConfig``, grouping them all;
- ``loading``: files and ``section.field`` overrides coerced into a ``RunConfig``, and saving one;
- ``methods``: the method presets (``--method``), overrides on top of a run's config.

Every name is imported from here (``from laneshift.config import RunConfig, METHODS``).

Room: the contract (shared by every process). May import: its own modules and the standard library
and PyYAML; no other laneshift module.
"""

from __future__ import annotations

from .loading import build_section, load_run_config, read_config_file, save_run_config
from .methods import METHODS, method_settings
from .checks import NAME, ConfigError
from .run import (AUTO_EVAL_FROM, SECTIONS, DeployConfig, RunConfig, TrainConfig, TransportConfig, worker_budgets,
                  worker_names)
from .sections import (DEMO_MODES, SCENARIO_NAMES, SHIELD_DECEL, SHIELD_GAP, ActorConfig, EnvConfig, LearnerConfig,
                       ReplayConfig)

__all__ = ["AUTO_EVAL_FROM", "DEMO_MODES", "METHODS", "NAME", "SCENARIO_NAMES", "SECTIONS", "SHIELD_DECEL",
           "SHIELD_GAP", "ActorConfig", "ConfigError", "DeployConfig", "EnvConfig", "LearnerConfig", "ReplayConfig", "RunConfig", "TrainConfig", "TransportConfig",
           "build_section", "load_run_config", "method_settings", "read_config_file", "save_run_config",
           "worker_budgets", "worker_names"]
