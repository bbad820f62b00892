"""Demo shards as Minari datasets: per-shard ids, per-step infos, a rebuildable env spec, and
shards written before these (one constant id, no infos) still loading.

Short episodes of the straight scenario (vector observations) and of LKA.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from laneshift.demos import (
    LEGACY_DATASET_ID,
    ShardError,
    load_shard,
    shard_dataset_id,
)
from laneshift.tools.demos.generate import generate_shard
from laneshift.tools.demos.writer import write_shard
from laneshift.tools.demos.cli import main
from laneshift.demos.envsupport import make_env
from laneshift.tools.demos.drivers import run_episode, scripted_driver
from laneshift.demos.shard import dataset_data_dir, read_metadata

STRAIGHT = "laneshift/StraightLaneChange-v0"
KWARGS = {"observation": "vector", "max_steps": 12}


@pytest.fixture(scope="module")
def straight(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("minari") / "straight"
    return generate_shard(out, env_id_or_scenario="straight", env_kwargs=KWARGS, episodes=2, seed=0)


def test_each_shard_has_its_own_valid_dataset_id(straight: Path, tmp_path: Path) -> None:
    from minari.dataset.minari_dataset import parse_dataset_id

    other = generate_shard(tmp_path / "other demos.v2", env_id_or_scenario="straight",
                           env_kwargs=KWARGS, episodes=1, seed=0, policy="human-like")
    ids = [read_metadata(straight)["dataset_id"], read_metadata(other)["dataset_id"]]
    assert ids == ["laneshift/straight-scripted-straight-v0",
                   "laneshift/straight-human-like-other_demos_v2-v0"]
    for dataset_id in ids:
        assert parse_dataset_id(dataset_id)[0] == "laneshift"
    assert dataset_data_dir(other) == other / "laneshift" / "straight-human-like-other_demos_v2-v0" / "data"
    assert shard_dataset_id("CartPole-v1", "human", "a/b") == "laneshift/CartPole-v1-human-a_b-v0"
    with pytest.raises(ValueError, match="recorded_by"):
        shard_dataset_id(STRAIGHT, "a person", "x")


def test_plain_minari_loads_it_by_its_id(straight: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import minari

    shard = load_shard(straight)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(straight))
    dataset = minari.load_dataset(shard.metadata["dataset_id"])
    assert dataset.total_steps == len(shard) and dataset.total_episodes == 2


def test_infos_are_stored_per_step(straight: Path) -> None:
    import minari

    meta = read_metadata(straight)
    assert {"crashed", "on_target_lane", "lane_index", "target_lane", "speed"} <= set(meta["info_keys"])
    env = make_env(STRAIGHT, KWARGS)
    try:
        reference = []
        for seed in (0, 1):
            reference.append(run_episode(env, scripted_driver(env), seed)["infos"])
    finally:
        env.close()
    dataset = minari.MinariDataset(dataset_data_dir(straight))
    for episode, infos in zip(dataset.iterate_episodes(), reference):
        steps = len(episode.actions)
        assert episode.infos["crashed"].shape == (steps + 1,)  # the reset info, then one per step
        assert episode.infos["crashed"].dtype == bool
        assert episode.infos["lane_index"].dtype == np.int64
        assert episode.infos["on_target_lane"].tolist() == [i["on_target_lane"] for i in infos]
        assert episode.infos["speed"].tolist() == pytest.approx([i["speed"] for i in infos])
    outcomes = meta["outcomes"]
    with h5py.File(dataset_data_dir(straight) / "main_data.hdf5") as f:
        for index, outcome in enumerate(outcomes):
            assert bool(f[f"episode_{index}/infos/crashed"][-1]) == outcome["crashed"]
            assert bool(f[f"episode_{index}/infos/on_target_lane"][-1]) == outcome["on_target_lane"]


def lka_episode(max_steps: int) -> dict:
    """One recorded LKA episode (action 15 every step, seed 0)."""
    env = make_env("laneshift/LaneKeepingAssist-v0", {"max_steps": max_steps})
    try:
        return run_episode(env, lambda obs: 15, 0)
    finally:
        env.close()


def test_no_infos_when_they_are_not_one_per_observation(tmp_path: Path) -> None:
    episode = lka_episode(max_steps=5)
    episode["infos"] = episode["infos"][1:]  # one per step only: not Minari's layout
    path = write_shard(tmp_path / "lka", [episode], env_id="laneshift/LaneKeepingAssist-v0",
                       env_kwargs={"max_steps": 5}, recorded_by="scripted", seeds=[0])
    assert read_metadata(path)["info_keys"] == []
    with h5py.File(dataset_data_dir(path) / "main_data.hdf5") as f:
        assert "infos" not in f["episode_0"]
    assert len(load_shard(path)) == 5


def test_env_spec_rebuilds_the_env_in_a_fresh_process(straight: Path) -> None:
    """A third party with laneshift installed but never imported: gymnasium.make(spec) works,
    and so does gymnasium.make on the recorded module-qualified id."""
    data = dataset_data_dir(straight)
    code = f"""
import json, sys
import gymnasium as gym
assert not any(m.startswith("laneshift") for m in sys.modules)
meta = json.load(open({str(data / 'metadata.json')!r}))
env = gym.make(gym.envs.registration.EnvSpec.from_json(meta["env_spec"]))
assert env.unwrapped.max_steps == 12, env.unwrapped.max_steps
env2 = gym.make(meta["laneshift"]["gymnasium_id"], **meta["laneshift"]["env_kwargs"])
assert env2.unwrapped.max_steps == 12 and env2.spec.id == "laneshift/StraightLaneChange-v0"
import minari
assert minari.MinariDataset({str(data)!r}).recover_environment().unwrapped.max_steps == 12
print("ok")
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=240, cwd=straight.parent)
    assert result.returncode == 0, result.stderr[-2000:]
    spec = json.loads(json.loads((data / "metadata.json").read_text())["env_spec"])
    assert spec["entry_point"] == "laneshift.actors.envs.lane_change:StraightLaneChangeEnv"
    assert spec["kwargs"] == KWARGS
    assert read_metadata(straight)["gymnasium_id"] == f"laneshift.actors.envs:{STRAIGHT}"


def test_render_mode_is_not_part_of_the_stored_spec(tmp_path: Path) -> None:
    env = make_env(STRAIGHT, KWARGS, render_mode="rgb_array")  # what the keyboard recorder builds
    try:
        episode = run_episode(env, lambda obs: 0, 3)
        path = write_shard(tmp_path / "rec", [episode], env_id=STRAIGHT, env_kwargs=KWARGS,
                           recorded_by="human", seeds=[3], env=env)
    finally:
        env.close()
    meta = json.loads((dataset_data_dir(path) / "metadata.json").read_text())
    assert json.loads(meta["env_spec"])["kwargs"] == KWARGS
    assert meta["dataset_id"] == "laneshift/straight-human-rec-v0"


def _make_legacy(shard: Path, out: Path) -> Path:
    """A shard exactly as written before per-shard ids: DIR/laneshift-demos-v0, no infos, no
    dataset_id / gymnasium_id / info_keys / driver in the laneshift metadata."""
    import shutil

    data = out / LEGACY_DATASET_ID / "data"
    shutil.copytree(dataset_data_dir(shard), data)
    meta_file = data / "metadata.json"
    meta = json.loads(meta_file.read_text())
    meta["dataset_id"] = LEGACY_DATASET_ID
    for key in ("dataset_id", "gymnasium_id", "info_keys", "driver"):
        meta["laneshift"].pop(key)
    meta_file.write_text(json.dumps(meta))
    with h5py.File(data / "main_data.hdf5", "a") as f:
        for name in list(f):
            del f[name]["infos"]
    return out


def test_shards_written_before_still_load(straight: Path, tmp_path: Path, capsys) -> None:
    legacy = _make_legacy(straight, tmp_path / "legacy")
    old, new = load_shard(legacy, env_id="straight", n_actions=9), load_shard(straight)
    assert old.sha256 == new.sha256 and len(old) == len(new)
    np.testing.assert_array_equal(old.observations, new.observations)
    assert old.metadata["dataset_id"] == LEGACY_DATASET_ID  # from Minari's own field
    assert dataset_data_dir(legacy) == legacy / LEGACY_DATASET_ID / "data"
    assert main(["inspect", str(legacy), "--png", str(tmp_path / "r.png")]) == 0
    assert "per-step infos: none" in capsys.readouterr().out


def test_a_directory_with_two_datasets_is_refused(straight: Path, tmp_path: Path) -> None:
    import shutil

    both = tmp_path / "both"
    shutil.copytree(straight, both)
    _make_legacy(straight, tmp_path / "tmp-legacy")
    shutil.copytree(tmp_path / "tmp-legacy" / LEGACY_DATASET_ID, both / "x" / "other-v0")
    with pytest.raises(ShardError, match="holds 2 datasets"):
        load_shard(both)
    assert len(load_shard(both / "laneshift" / "straight-scripted-straight-v0")) == len(load_shard(straight))


def test_bad_dataset_id_is_refused_before_writing(tmp_path: Path) -> None:
    episode = lka_episode(max_steps=3)
    with pytest.raises(ValueError, match="not a Minari id"):
        write_shard(tmp_path / "bad", [episode], env_id="laneshift/LaneKeepingAssist-v0",
                    env_kwargs={"max_steps": 3}, recorded_by="scripted", seeds=[0],
                    dataset_id="no version")
    assert not (tmp_path / "bad").exists()
