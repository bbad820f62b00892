"""The grayscale frame options of the run config (env.frame_supersample, env.frame_interval,
env.frame_centering, env.frame_scale), each the same way: validated (a bad value and a vector run refused with the
option's name), passed to the env only when set, its own demo shard name (the frames differ, so the
demonstrations do), and recorded in a checkpoint so that an evaluation rebuilds the same env.
What each option draws is tested beside its code's other tests (test_frame_supersample.py,
test_frame_interval.py, test_frame_view.py).

Room: tests, unit. May import: laneshift (any floor), pytest, the standard library and what the code
under test needs."""

from __future__ import annotations

import pytest

from laneshift.actors.evaluation import checkpoint_env_settings
from laneshift.config import ConfigError, EnvConfig, load_run_config
from laneshift.deploy.run_dir import default_demo_dir
from laneshift.envspec import RECORDED_ENV_OPTIONS

# option, a value to set, a value out of range, the shard name's suffix for the value, its default
OPTIONS = [
    ("frame_supersample", 4, 9, "-ss4-", 1),
    ("frame_interval", 3, 31, "-fi3-", 1),
    ("frame_centering", 0.3, 1.0, "-c0.3-", 0.5),
    ("frame_scale", 1.0, 9.0, "-px1-", 2.0),
]


@pytest.mark.parametrize("option, value, bad, suffix, default", OPTIONS, ids=[o[0] for o in OPTIONS])
def test_a_frame_option_is_validated_passed_on_named_in_the_shard_and_recorded(option, value, bad, suffix,
                                                                                default):
    with pytest.raises(ConfigError, match=f"env.{option}"):
        EnvConfig(observation="grayscale", **{option: bad})
    with pytest.raises(ConfigError, match="needs env.observation=grayscale"):
        EnvConfig(observation="vector", **{option: value})
    cfg = load_run_config(overrides={"env.observation": "grayscale", f"env.{option}": value,
                                     "train.run_dir": "runs/x"})
    assert getattr(cfg.env, option) == value and cfg.env.env_kwargs()[option] == value
    assert default_demo_dir(cfg, 40).name.startswith(f"straight-grayscale4x100x100{suffix}")
    plain = cfg.replace(env=EnvConfig(observation="grayscale"))
    assert getattr(plain.env, option) == default and option not in plain.env.env_kwargs()
    assert default_demo_dir(plain, 40).name.startswith("straight-grayscale4x100x100-p")
    # The learner writes the option where the run set it; an evaluation reads it back with its type.
    assert option in RECORDED_ENV_OPTIONS
    settings = checkpoint_env_settings({"obs_shape": "4,100,100", "obs_dtype": "|u1", option: str(value)})
    assert settings == {"observation": "grayscale", option: value}
    assert type(settings[option]) is type(value)
    assert EnvConfig(**settings).env_kwargs()[option] == value
