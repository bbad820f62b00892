"""``laneshift.config``: defaults, files (YAML/TOML/JSON), CLI-style overrides, refusals.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import dataclasses
import json
import typing

import pytest

from laneshift.config import (
    SECTIONS,
    ActorConfig,
    ConfigError,
    EnvConfig,
    LearnerConfig,
    ReplayConfig,
    RunConfig,
    TrainConfig,
    TransportConfig,
    build_section,
    load_run_config,
    read_config_file,
    save_run_config,
)


def refused(overrides: dict, prefix: str) -> str:
    """The ConfigError ``overrides`` give, which must start with ``prefix``. Unless ``prefix`` asks
    for it, "unknown field" fails: a field that was renamed or removed must not pass as a bad value
    of itself (the two messages share the ``section.field: `` prefix)."""
    with pytest.raises(ConfigError) as info:
        load_run_config(overrides=overrides)
    msg = str(info.value)
    assert msg.startswith(prefix), msg
    if "unknown field" not in prefix:
        assert not msg.startswith(prefix.split(":")[0] + ": unknown field"), msg
    return msg


# --------------------------------------------------------------------------- defaults


def test_defaults_are_valid():
    cfg = RunConfig()
    assert load_run_config() == cfg
    for name, cls in SECTIONS.items():
        assert getattr(cfg, name) == cls()
    assert cfg.to_dict()["learner"]["hidden"] == [256, 256]
    assert cfg.to_dict()["replay"]["demo_paths"] == []
    json.dumps(cfg.to_dict())  # plain JSON types only


def test_configs_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        RunConfig().learner.lr = 1.0  # type: ignore[misc]


def test_env_kwargs():
    assert EnvConfig().env_kwargs() == {"observation": "vector", "reward_preset": 5, "initial_lane": "random",
                                        "action_set": "paper"}
    assert EnvConfig(max_steps=50, policy_vehicles=2).env_kwargs()["max_steps"] == 50
    assert EnvConfig(scenario="lka").env_kwargs() == {} and EnvConfig(scenario="lka", max_steps=9).env_kwargs() == {
        "max_steps": 9}
    assert EnvConfig(scenario="laneshift/LaneKeepingAssist-v0").is_lka


# --------------------------------------------------------------------------- files

YAML = """
env:
  scenario: merge
  observation: grayscale
actor:
  workers: 3
  exploration: apex
replay:
  capacity: 5000
  demo_mode: retention
  demo_paths: [runs/demos/a, runs/demos/b]
  min_size: 100
learner:
  hidden: [64, 32]
  lr: 1.0e-3
  double: false
train:
  env_steps: 2e4
"""

TOML = """
[env]
scenario = "merge"
observation = "grayscale"

[actor]
workers = 3
exploration = "apex"

[replay]
capacity = 5000
demo_mode = "retention"
demo_paths = ["runs/demos/a", "runs/demos/b"]
min_size = 100

[learner]
hidden = [64, 32]
lr = 1e-3
double = false

[train]
env_steps = 20000
"""

JSON = {"env": {"scenario": "merge", "observation": "grayscale"}, "actor": {"workers": 3, "exploration": "apex"},
        "replay": {"capacity": 5000, "demo_mode": "retention", "demo_paths": ["runs/demos/a", "runs/demos/b"],
                   "min_size": 100},
        "learner": {"hidden": [64, 32], "lr": 0.001, "double": False}, "train": {"env_steps": 20000}}


def _check_loaded(cfg: RunConfig) -> None:
    assert cfg.env.scenario == "merge" and cfg.env.observation == "grayscale"
    assert cfg.actor.workers == 3 and cfg.actor.exploration == "apex"
    assert cfg.replay.capacity == 5000 and cfg.replay.demo_paths == ("runs/demos/a", "runs/demos/b")
    assert cfg.learner.hidden == (64, 32) and cfg.learner.lr == 1e-3 and cfg.learner.double is False
    assert cfg.train.env_steps == 20000 and isinstance(cfg.train.env_steps, int)
    assert cfg.transport == TransportConfig()  # untouched sections keep their defaults


@pytest.mark.parametrize("suffix,text", [(".yaml", YAML), (".yml", YAML), (".toml", TOML), (".json", json.dumps(JSON))])
def test_files_load(tmp_path, suffix, text):
    path = tmp_path / f"run{suffix}"
    path.write_text(text)
    _check_loaded(load_run_config(path))


def test_overrides_beat_the_file(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text(YAML)
    cfg = load_run_config(path, overrides={"actor.workers": "5", "learner.hidden": "8"})
    assert cfg.actor.workers == 5 and cfg.learner.hidden == (8,) and cfg.env.scenario == "merge"


def test_base_config():
    base = RunConfig(actor=ActorConfig(workers=4))
    assert load_run_config(base=base, overrides={"actor.seed": 3}).actor.workers == 4


def test_empty_yaml_is_the_defaults(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("")
    assert load_run_config(path) == RunConfig()


@pytest.mark.parametrize("name,text,needle", [
    ("bad.yaml", "env: [unclosed", "not valid yaml"),
    ("bad.toml", "[env\nscenario=", "not valid toml"),
    ("bad.json", "{", "not valid json"),
    ("list.yaml", "- 1\n- 2\n", "top level must be a mapping"),
    ("sect.yaml", "env: 5\n", "section 'env' must be a mapping"),
    ("unknown.yaml", "bogus: {x: 1}\n", "unknown section 'bogus'"),
])
def test_bad_files(tmp_path, name, text, needle):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_run_config(path)
    assert str(info.value).startswith(f"config file {path}") and needle in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="config file .*nope.yaml"):
        read_config_file(tmp_path / "nope.yaml")


def test_unknown_field_in_a_file_names_it(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text("[learner]\nlearning_rate = 0.1\n")
    with pytest.raises(ConfigError) as info:
        load_run_config(path)
    assert str(info.value).startswith("learner.learning_rate: unknown field")


def test_bad_value_in_a_file_names_it(tmp_path):
    path = tmp_path / "run.json"
    path.write_text(json.dumps({"replay": {"demo_ratio": 1.5}}))
    with pytest.raises(ConfigError) as info:
        load_run_config(path)
    assert str(info.value) == "replay.demo_ratio: must be in (0, 1), got 1.5"


# --------------------------------------------------------------------------- CLI-style overrides


@pytest.mark.parametrize("key,raw,value", [
    ("train.env_steps", "2e4", 20000), ("train.env_steps", "20000", 20000), ("train.env_steps", "1_000", 1000),
    ("train.env_steps", 3.0, 3), ("train.env_steps", "1E3", 1000),
    ("learner.lr", "1e-3", 1e-3), ("learner.lr", "0.5", 0.5), ("learner.lr", 2, 2.0),
    ("learner.double", "false", False), ("learner.double", "True", True), ("learner.double", "no", False),
    ("learner.double", "ON", True), ("learner.double", "0", False), ("learner.double", "1", True),
    ("learner.double", False, False),
    ("learner.hidden", "64,64", (64, 64)), ("learner.hidden", "128", (128,)), ("learner.hidden", " 8 , 4 ", (8, 4)),
    ("learner.hidden", [32, "16"], (32, 16)), ("learner.hidden", "64,64,", (64, 64)),
    ("learner.hidden", "[512, 512]", (512, 512)), ("learner.hidden", "(32,16)", (32, 16)),
    ("replay.demo_paths", "a,b", ("a", "b")), ("replay.demo_paths", "", ()), ("replay.demo_paths", ["x"], ("x",)),
    ("env.scenario", "lka", "lka"), ("env.scenario", "laneshift/StraightLaneChange-v0", "laneshift/StraightLaneChange-v0"),
    ("transport.run_id", "exp-1_b", "exp-1_b"), ("transport.timeout_s", "2", 2.0),
])
def test_overrides_coerce(key, raw, value):
    section, name = key.split(".")
    got = getattr(getattr(load_run_config(overrides={key: raw}), section), name)
    assert got == value and type(got) is type(value)


def test_str_field_accepts_numbers_as_text():
    assert load_run_config(overrides={"train.run_dir": 5}).train.run_dir == "5"


# --------------------------------------------------------------------------- refusals: every check

BAD_VALUES = [
    ("env.scenario", "highway"), ("env.observation", "rgb"), ("env.reward_preset", 0), ("env.reward_preset", 6),
    ("env.max_steps", -1), ("env.initial_lane", "left"), ("env.action_set", "all"), ("env.policy_vehicles", -1),
    ("actor.workers", 0), ("actor.envs_per_worker", 0), ("actor.send_every", 0), ("actor.exploration", "boltzmann"),
    ("actor.epsilon_start", 1.5), ("actor.epsilon_start", -0.1), ("actor.epsilon_final", 2),
    ("actor.apex_epsilon", -1), ("actor.epsilon_decay_steps", -1), ("actor.epsilon_decay_rate", 1.0),
    ("actor.epsilon_decay_rate", -0.1), ("actor.torch_threads", 0),
    ("replay.capacity", 1), ("replay.demo_mode", "mixed"), ("replay.demo_ratio", 0.0), ("replay.demo_ratio", 1.0),
    ("replay.min_size", 0), ("replay.min_size", 100_001), ("replay.samples_per_insert", -1),
    ("replay.spi_tolerance", -1),
    ("learner.lr", 0), ("learner.lr", -1e-3), ("learner.gamma", 1.01), ("learner.gamma", -0.1),
    ("learner.batch_size", 0), ("learner.batch_size", 8193), ("learner.hidden", ""), ("learner.hidden", "64,0"),
    ("learner.target_update_period", 0), ("learner.publish_every", 0), ("learner.updates_per_round", 0),
    ("learner.phase1_updates", 0), ("learner.checkpoint_every", 0), ("learner.prefetch", 0), ("learner.prefetch", 65),
    ("learner.torch_threads", 0), ("learner.heads", 0), ("learner.huber_delta", 0), ("learner.grad_clip", 0),
    ("learner.weight_decay", -1),
    ("transport.router", "127.0.0.1:7447"), ("transport.router", "http://x"), ("transport.run_id", "a/b"),
    ("transport.run_id", ""), ("transport.run_id", "x" * 65), ("transport.run_id", "a b"), ("transport.timeout_s", 0),
    ("train.env_steps", 0), ("train.parallel", "both"), ("train.log_every_s", 0), ("train.eval_episodes", -1),
]


@pytest.mark.parametrize("key,value", BAD_VALUES)
def test_bad_values_refused_naming_the_field(key, value):
    msg = refused({key: value}, key + ": ")
    assert ", got " in msg


@pytest.mark.parametrize("mode", ["retention", "rehearsal"])
def test_demo_modes_without_paths_are_valid_config(mode):
    # `train` fills in the scripted demonstrator's shard; a bare replay server refuses to start.
    assert load_run_config(overrides={"replay.demo_mode": mode}).replay.demo_paths == ()
    cfg = load_run_config(overrides={"replay.demo_mode": mode, "replay.demo_paths": "runs/demos/x"})
    assert cfg.replay.demo_paths == ("runs/demos/x",)


def test_one_head_per_road_only_on_allroads_with_one_head_for_each_road():
    from laneshift.envspec import ALLROADS

    assert load_run_config(overrides={"env.scenario": "allroads", "learner.heads": len(ALLROADS)}).learner.heads == 4
    msg = refused({"learner.heads": 4}, "learner.heads: one head per road takes env.scenario=allroads")
    assert "'straight'" in msg
    refused({"env.scenario": "allroads", "learner.heads": 3}, "learner.heads: one head per road")


def test_validation_seed_below_zero_is_refused():
    """train.validation_seed: the first episode seed of the greedy evaluation during training."""
    assert TrainConfig().validation_seed == 200_000
    msg = refused({"train.validation_seed": -1}, "train.validation_seed: ")
    assert msg == "train.validation_seed: must be >= 0, got -1"
    assert load_run_config(overrides={"train.validation_seed": "0"}).train.validation_seed == 0


def test_min_size_above_capacity_named():
    msg = refused({"replay.capacity": 100, "replay.min_size": 101}, "replay.min_size: ")
    assert "replay.capacity (100)" in msg


@pytest.mark.parametrize("key,raw", [
    ("train.env_steps", "2.5e0"), ("train.env_steps", "abc"), ("train.env_steps", 2.5), ("train.env_steps", True),
    ("train.env_steps", [1]), ("train.env_steps", None), ("learner.lr", "fast"), ("learner.lr", True),
    ("learner.lr", None), ("learner.double", "maybe"), ("learner.double", 1), ("learner.double", None),
    ("learner.hidden", 64), ("learner.hidden", "a,b"), ("learner.hidden", {"a": 1}), ("env.scenario", True),
    ("env.scenario", None), ("env.scenario", ["lka"]), ("replay.demo_paths", 5),
])
def test_bad_types_refused_naming_the_field(key, raw):
    refused({key: raw}, key + ": ")


@pytest.mark.parametrize("key", ["learner.learning_rate", "env.speed", "replay.size"])
def test_unknown_fields_refused(key):
    msg = refused({key: 1}, key + ": unknown field")
    assert "known:" in msg


@pytest.mark.parametrize("key", ["bogus.x", "learnerlr", "learner.", ".lr"])
def test_unknown_sections_or_malformed_override_keys_refused(key):
    refused({key: 1}, key + ": overrides are written section.field")


def test_build_section_directly():
    assert build_section("learner", {"hidden": "4,4"}).hidden == (4, 4)
    with pytest.raises(ConfigError, match=r"^actor\.nope: unknown field"):
        build_section("actor", {"nope": 1})


@pytest.mark.parametrize("key", [f"{s}.{f.name}" for s, cls in SECTIONS.items() for f in dataclasses.fields(cls)
                                 if typing.get_type_hints(cls)[f.name] is float])
def test_nan_is_refused_for_every_float_field(key):
    """Every float field's check is false for NaN, so NaN is refused by name. A field with no
    check would let it through: a NaN ``actor.apex_alpha``, say, makes every apex epsilon NaN
    (``rng.random() < nan`` is False: silently greedy forever)."""
    refused({key: "nan"}, key + ": ")


def test_negative_apex_alpha_refused():
    """A negative ``actor.apex_alpha`` would give apex epsilons above 1."""
    refused({"actor.apex_alpha": -1.0}, "actor.apex_alpha: ")


def test_a_removed_field_does_not_pass_as_a_bad_value():
    """``refused`` tells "unknown field" from a bad value: ``actor.weights_poll_s`` is gone."""
    with pytest.raises(AssertionError):
        refused({"actor.weights_poll_s": -1.0}, "actor.weights_poll_s: ")


@pytest.mark.parametrize("key", ["replay.seed", "actor.seed"])
def test_negative_seeds_refused(key):
    """A negative seed is refused by name: ``np.random.default_rng(-1)`` would raise "expected
    non-negative integer" later, inside the replay server (``replay.seed``) or every env worker's
    policy (``actor.seed``), in a message that names no field."""
    refused({key: -1}, key + ": ")


# --------------------------------------------------------------------------- RunConfig deadlock check


def test_spi_tolerance_must_cover_one_sample_request():
    # batch 256 x max(prefetch 4, updates_per_round 8) = 2048 rows per request
    msg = refused({"replay.spi_tolerance": 2047}, "replay.spi_tolerance: ")
    assert "2048" in msg
    assert load_run_config(overrides={"replay.spi_tolerance": 2048}).replay.spi_tolerance == 2048.0
    refused({"learner.batch_size": 512, "learner.prefetch": 20, "replay.spi_tolerance": 10239},
            "replay.spi_tolerance: ")
    load_run_config(overrides={"learner.batch_size": 512, "learner.prefetch": 20, "replay.spi_tolerance": 10240})
    # Without a ratio there is no limiter, so no deadlock either.
    load_run_config(overrides={"replay.samples_per_insert": 0, "replay.spi_tolerance": 0})


def test_deadlock_check_on_direct_construction():
    with pytest.raises(ConfigError, match=r"^replay\.spi_tolerance"):
        RunConfig(learner=LearnerConfig(batch_size=64, prefetch=4, updates_per_round=8),
                  replay=ReplayConfig(spi_tolerance=511))
    RunConfig(learner=LearnerConfig(batch_size=64, prefetch=4, updates_per_round=8), replay=ReplayConfig(spi_tolerance=512))


# --------------------------------------------------------------------------- save / load


def test_save_load_round_trip(tmp_path):
    cfg = load_run_config(overrides={
        "env.scenario": "roundabout", "env.max_steps": 77, "actor.workers": 4, "actor.exploration": "exponential",
        "replay.demo_mode": "rehearsal", "replay.demo_paths": "a,b", "replay.capacity": 5000, "replay.min_size": 10,
        "learner.hidden": "32,16,8", "learner.double": "false", "learner.gamma": 0.95, "transport.run_id": "r-1",
        "train.parallel": "sync", "train.run_dir": str(tmp_path / "run")})
    path = save_run_config(cfg, tmp_path / "sub" / "config.yaml")
    assert path.exists()
    assert load_run_config(path) == cfg
    assert load_run_config(path).to_dict() == cfg.to_dict()


def test_saved_file_is_plain_yaml_with_one_section_per_component(tmp_path):
    import yaml

    path = save_run_config(RunConfig(), tmp_path / "c.yaml")
    data = yaml.safe_load(path.read_text())
    assert list(data) == list(SECTIONS) and data["learner"]["hidden"] == [256, 256]


def test_replace_and_to_dict():
    cfg = RunConfig().replace(train=TrainConfig(env_steps=5))
    assert cfg.train.env_steps == 5 and cfg.to_dict()["train"]["env_steps"] == 5


def test_every_named_method_builds_a_valid_config():
    from laneshift.config import METHODS, load_run_config, method_settings

    for name in METHODS:
        cfg = load_run_config(overrides=method_settings(name))
        assert cfg.replay.demo_mode in ("none", "retention", "rehearsal", "dqfd"), name
    anneal = load_run_config(overrides=method_settings("dqfd-bc-anneal"))
    assert (anneal.learner.lr_final, anneal.learner.ema_decay, anneal.actor.epsilon_final) == (5e-5, 0.999, 0.01)
    assert anneal.learner.bc_loss_weight == 1.0 and anneal.learner.n_step == 10  # dqfd-bc underneath


def test_the_pixel_preset_is_the_command_line_of_the_pixel_runs():
    # dqfd-bc-pixels names the --set flags of probe 18's runs; the run's own recorded config (the
    # protocol's json of seed 2, docs/results/pixels-probe-lp-fp32/) is the reference, field by field.
    from pathlib import Path

    from laneshift.config import method_settings

    recorded = json.loads((Path(__file__).parents[1] / "docs/results/pixels-probe-lp-fp32/seed2.json").read_text())
    assert recorded["method"] == "dqfd-bc-anneal" and "--set learner.frozen_steps=150000" in recorded["command"]
    cfg = load_run_config(overrides={**method_settings("dqfd-bc-pixels"), "env.scenario": "straight",
                                     "actor.seed": 2, "learner.seed": 2, "replay.seed": 2})
    ours = json.loads(json.dumps(cfg.to_dict()))
    wiring = {"demo_paths", "http_port", "metrics_port"}  # the protocol sets them per run (its shard, free ports)
    for section in ("env", "actor", "replay", "learner"):
        differ = {k: (v, ours[section].get(k)) for k, v in recorded["config"][section].items()
                  if k in ours[section] and k not in wiring and ours[section][k] != v}
        assert not differ, (section, differ)


def test_alongside_features_need_the_lane_features_and_reach_the_env():
    cfg = load_run_config(overrides={"env.alongside_features": "true", "env.scenario": "merge"})
    assert cfg.env.env_kwargs()["alongside_features"] is True
    assert "alongside_features" not in load_run_config().env.env_kwargs()  # off: the env's default layout
    with pytest.raises(ConfigError, match="env.alongside_features: extends the lane features"):
        load_run_config(overrides={"env.alongside_features": "true", "env.lane_features": "false"})
