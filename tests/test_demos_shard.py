"""Demo shards: generate -> load round trip, Minari compatibility, refusal of bad shards.

Uses laneshift's LKA env (fast, pure numpy) with a small proportional steering policy, and a
tiny in-test env whose observations are shifting uint8 frame stacks like highway-env's
grayscale observation.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import h5py
import numpy as np
import pytest

from laneshift.demos import (
    ShardError,
    load_shard,
    load_shards,
)
from laneshift.tools.demos.generate import generate_shard
from laneshift.tools.demos.writer import write_shard
from laneshift.demos.checksum import episodes_sha256, transition_sha256
from laneshift.demos.framestack import rebuild_frame_stacks, split_frame_stacks
from laneshift.demos.shard import dataset_data_dir

LKA = "laneshift/LaneKeepingAssist-v0"
LKA_KWARGS = {"max_steps": 20}


class SteerBack:
    """Policy factory shaped like ScriptedDriver: steer against the lateral error e1."""

    def __init__(self, env: gym.Env) -> None:
        self.n = int(env.action_space.n)

    def __call__(self, obs: np.ndarray) -> int:
        return int(np.clip(round(15 - 40 * obs[0] - 20 * obs[1]), 0, self.n - 1))


def reference_rollout(env_id, kwargs, seeds, policy):
    """Transitions collected independently of laneshift.demos (the test's ground truth)."""
    import laneshift.actors.envs  # noqa: F401  (registers the ids)

    env = gym.make(env_id, **kwargs)
    env.action_space.seed(seeds[0])
    cols = {k: [] for k in ("obs", "act", "rew", "next", "term", "trunc", "ep")}
    for episode, seed in enumerate(seeds):
        obs, _ = env.reset(seed=seed)
        driver = policy(env)
        while True:
            action = driver(obs)
            nxt, reward, term, trunc, _ = env.step(action)
            for key, value in zip(cols, (obs, action, reward, nxt, term, trunc, episode)):
                cols[key].append(np.array(value, copy=True))
            obs = nxt
            if term or trunc:
                break
    env.close()
    return {k: np.stack(v) for k, v in cols.items()}


@pytest.fixture(scope="module")
def lka_shard(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shards") / "lka"
    return generate_shard(out, env_id_or_scenario="lka", env_kwargs=LKA_KWARGS, episodes=4,
                          seed=7, policy=SteerBack)


def test_round_trip_equals_what_the_env_produced(lka_shard: Path) -> None:
    shard = load_shard(lka_shard, env_id=LKA, obs_shape=(6,), obs_dtype=np.float32, n_actions=31)
    ref = reference_rollout(LKA, LKA_KWARGS, [7, 8, 9, 10], SteerBack)
    np.testing.assert_array_equal(shard.observations, ref["obs"])
    np.testing.assert_array_equal(shard.next_observations, ref["next"])
    np.testing.assert_array_equal(shard.actions, ref["act"])
    np.testing.assert_array_equal(shard.rewards, ref["rew"].astype(np.float32))
    np.testing.assert_array_equal(shard.terminations, ref["term"])
    np.testing.assert_array_equal(shard.truncations, ref["trunc"])
    np.testing.assert_array_equal(shard.episode_ids, ref["ep"])
    assert shard.observations.dtype == np.float32 and shard.actions.dtype == np.int64
    assert shard.rewards.dtype == np.float32 and shard.episode_ids.dtype == np.int32
    assert shard.terminations.dtype == bool and shard.truncations.dtype == bool

    meta = shard.metadata
    assert len(shard) == meta["steps"] == len(ref["act"])
    assert meta["episodes"] == 4 and meta["seeds"] == [7, 8, 9, 10]
    assert meta["env_id"] == LKA and meta["env_kwargs"] == LKA_KWARGS
    assert meta["n_actions"] == 31 and meta["obs_shape"] == (6,) and meta["obs_dtype"] == "float32"
    assert meta["recorded_by"] == "scripted" and meta["observation"] == "vector"
    assert meta["obs_encoding"] == "full"
    assert meta["survival_rate"] is not None  # LKA reports "crashed" (|e1| > 1 m)
    assert shard.sha256 == transition_sha256(
        shard.observations, shard.actions, shard.rewards, shard.next_observations,
        shard.terminations, shard.truncations, shard.episode_ids)


def test_same_seed_same_checksum(lka_shard: Path, tmp_path: Path) -> None:
    again = generate_shard(tmp_path / "again", env_id_or_scenario=LKA, env_kwargs=LKA_KWARGS,
                           episodes=4, seed=7, policy=SteerBack)
    assert load_shard(again).sha256 == load_shard(lka_shard).sha256


def test_a_shard_of_achieved_episodes_only_drives_on_until_it_has_its_count(tmp_path: Path) -> None:
    """achieved_only: episodes that do not end alive on the target lane (here: 40 steps are too few
    for some lane changes) are driven and left out; the shard holds the count asked, every one of
    them on the target lane at its end, with the seeds they were driven with."""
    path = generate_shard(tmp_path / "ok", env_id_or_scenario="straight", env_kwargs={"max_steps": 40},
                          episodes=4, seed=0, achieved_only=True)
    shard = load_shard(path)
    meta = shard.metadata
    assert meta["episodes"] == 4 and meta["achievement_rate"] == 1.0 and meta["achieved_only"] is True
    assert meta["discarded_episodes"] > 0 and len(set(meta["seeds"])) == 4
    assert meta["driven_achievement_rate"] == pytest.approx(4 / (4 + meta["discarded_episodes"]), abs=1e-6)
    plain = load_shard(generate_shard(tmp_path / "all", env_id_or_scenario="straight", env_kwargs={"max_steps": 40},
                                      episodes=max(meta["seeds"]) + 1, seed=0))
    assert plain.metadata["achievement_rate"] < 1.0  # the same driver on every seed misses some
    with pytest.raises(ValueError, match="does not report"):  # LKA has no target lane
        generate_shard(tmp_path / "lka", env_id_or_scenario="lka", env_kwargs=LKA_KWARGS, episodes=1, seed=0,
                       policy=SteerBack, achieved_only=True)
    with pytest.raises(ValueError, match="fewer than the 2 asked"):  # 5 steps: no lane change ever ends
        generate_shard(tmp_path / "none", env_id_or_scenario="straight",
                       env_kwargs={"max_steps": 5, "initial_lane": "non-target"}, episodes=2, seed=0,
                       achieved_only=True)


def test_plain_minari_reads_it(lka_shard: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import minari

    shard = load_shard(lka_shard)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(lka_shard))
    dataset = minari.load_dataset(shard.metadata["dataset_id"])  # the shard's own id
    assert dataset.total_episodes == 4 and dataset.total_steps == len(shard)
    assert dataset.action_space == gym.spaces.Discrete(31)
    for episode in dataset.iterate_episodes():
        rows = shard.episode_ids == episode.id
        np.testing.assert_array_equal(episode.observations[:-1], shard.observations[rows])
        np.testing.assert_array_equal(episode.observations[1:], shard.next_observations[rows])
        np.testing.assert_array_equal(episode.actions, shard.actions[rows])
    assert dataset.recover_environment().spec.kwargs["max_steps"] == 20
    assert minari.MinariDataset(dataset_data_dir(lka_shard)).total_steps == len(shard)


# ----------------------------------------------------------------------------- frame stacks


class StackEnv(gym.Env):
    """Tiny env with (4, 12, 10) uint8 frame-stack observations (newest frame last)."""

    def __init__(self, shifting: bool = True, steps: int = 6) -> None:
        self.observation_space = gym.spaces.Box(0, 255, (4, 12, 10), np.uint8)
        self.action_space = gym.spaces.Discrete(9)
        self.shifting, self.steps = shifting, steps

    def _frame(self) -> np.ndarray:
        return self.np_random.integers(0, 256, (12, 10), dtype=np.uint8)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.on_target = seed is not None and seed % 2 == 0  # "achieved" in even-seed episodes
        self.stack = np.zeros((4, 12, 10), np.uint8)
        self.stack[-1] = self._frame()
        return self.stack, {"crashed": False, "on_target_lane": False}

    def step(self, action):
        self.t += 1
        if self.shifting:
            self.stack = np.roll(self.stack, -1, axis=0)  # highway-env's update, in place
            self.stack[-1] = self._frame()
        else:
            self.stack = self.np_random.integers(0, 256, (4, 12, 10), dtype=np.uint8)
        done = self.t >= self.steps
        info = {"crashed": False, "on_target_lane": self.on_target}
        return self.stack, float(action), False, done, info


if "laneshift-test/Stack-v0" not in gym.registry:
    gym.register("laneshift-test/Stack-v0", entry_point=StackEnv)


def _cycle_policy(env: gym.Env):
    counter = iter(range(10**6))
    return lambda obs: next(counter) % 9


@pytest.mark.parametrize("shifting, encoding", [(True, "frame_stack"), (False, "full")])
def test_frame_stacks_round_trip(tmp_path: Path, shifting: bool, encoding: str) -> None:
    kwargs = {"shifting": shifting}
    path = generate_shard(tmp_path / "s", env_id_or_scenario="laneshift-test/Stack-v0",
                          env_kwargs=kwargs, episodes=3, seed=1, policy=_cycle_policy)
    shard = load_shard(path, obs_shape=(4, 12, 10), obs_dtype="uint8")
    ref = reference_rollout("laneshift-test/Stack-v0", kwargs, [1, 2, 3], _cycle_policy)
    np.testing.assert_array_equal(shard.observations, ref["obs"])
    np.testing.assert_array_equal(shard.next_observations, ref["next"])
    assert shard.metadata["obs_encoding"] == encoding
    assert shard.metadata["observation"] == "grayscale"
    assert shard.metadata["survival_rate"] == 1.0
    assert shard.metadata["achievement_rate"] == pytest.approx(1 / 3)  # seeds 1, 2, 3


def test_frame_stack_storage_is_smaller(tmp_path: Path) -> None:
    sizes = {}
    for shifting in (True, False):
        path = generate_shard(tmp_path / f"s{int(shifting)}", env_id_or_scenario=
                              "laneshift-test/Stack-v0", env_kwargs={"shifting": shifting,
                              "steps": 40}, episodes=2, seed=0, policy=_cycle_policy)
        with h5py.File(dataset_data_dir(path) / "main_data.hdf5") as f:
            sizes[shifting] = f["episode_0/observations"].nbytes
    assert sizes[True] * 4 == sizes[False]


def test_framestack_helpers() -> None:
    frames = np.arange(9 * 2 * 3, dtype=np.uint8).reshape(9, 2, 3)
    stacks = np.stack([frames[t:t + 4] for t in range(6)])
    prefix, newest = split_frame_stacks(stacks)
    np.testing.assert_array_equal(rebuild_frame_stacks(prefix, newest), stacks)
    broken = stacks.copy()
    broken[3, 0, 0, 0] += 1
    assert split_frame_stacks(broken) is None
    assert split_frame_stacks(stacks[:, :1]) is None  # single-frame "stacks"


def test_episode_and_flat_checksums_agree(lka_shard: Path) -> None:
    s = load_shard(lka_shard)
    starts = np.flatnonzero(np.diff(s.episode_ids, prepend=-1))
    ends = list(starts[1:]) + [len(s)]
    obs = [np.concatenate([s.observations[a:b], s.next_observations[b - 1:b]])
           for a, b in zip(starts, ends)]
    parts = lambda x: [x[a:b] for a, b in zip(starts, ends)]  # noqa: E731
    assert episodes_sha256(obs, parts(s.actions), parts(s.rewards.astype(np.float64)),
                           parts(s.terminations), parts(s.truncations), np.float32) == s.sha256


# ----------------------------------------------------------------------------- refusals


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_bad_checksum_is_refused(lka_shard: Path, tmp_path: Path) -> None:
    bad = _copy(lka_shard, tmp_path / "bad")
    with h5py.File(dataset_data_dir(bad) / "main_data.hdf5", "a") as f:
        f["episode_2/rewards"][3] += 1.0
    with pytest.raises(ShardError, match=r"sha256 mismatch") as info:
        load_shard(bad)
    assert str(bad) in str(info.value)


def test_tampered_metadata_checksum_is_refused(lka_shard: Path, tmp_path: Path) -> None:
    bad = _copy(lka_shard, tmp_path / "bad")
    meta_file = dataset_data_dir(bad) / "metadata.json"
    meta = json.loads(meta_file.read_text())
    meta["laneshift"]["sha256"] = "0" * 64
    meta_file.write_text(json.dumps(meta))
    with pytest.raises(ShardError, match=r"sha256 mismatch"):
        load_shard(bad)


def test_wrong_stored_shape_is_refused(lka_shard: Path, tmp_path: Path) -> None:
    bad = _copy(lka_shard, tmp_path / "bad")
    with h5py.File(dataset_data_dir(bad) / "main_data.hdf5", "a") as f:
        obs = f["episode_1/observations"][()]
        del f["episode_1/observations"]
        f["episode_1"].create_dataset("observations", data=obs[:, :5])
    with pytest.raises(ShardError, match=r"episode_1/observations shape \(\d+,5\)"):
        load_shard(bad)


def test_truncated_file_is_refused(lka_shard: Path, tmp_path: Path) -> None:
    bad = _copy(lka_shard, tmp_path / "bad")
    h5 = dataset_data_dir(bad) / "main_data.hdf5"
    h5.write_bytes(h5.read_bytes()[:2000])
    with pytest.raises(ShardError, match=r"cannot read .*main_data\.hdf5"):
        load_shard(bad)


def test_mismatch_with_the_run_is_named(lka_shard: Path) -> None:
    with pytest.raises(ShardError, match=r"observation shape \(6,\) != the run's env \(4,100,100\)"):
        load_shard(lka_shard, obs_shape=(4, 100, 100))
    with pytest.raises(ShardError) as info:
        load_shard(lka_shard, env_id="straight")
    assert "env_id 'laneshift/LaneKeepingAssist-v0' != the run's env " \
           "'laneshift/StraightLaneChange-v0'" in str(info.value)
    with pytest.raises(ShardError, match=r"observation dtype float32 != the run's env uint8"):
        load_shard(lka_shard, obs_dtype=np.uint8)
    with pytest.raises(ShardError, match=r"31 actions != the run's env 9"):
        load_shard(lka_shard, n_actions=9)
    assert f"demo shard {lka_shard}:" in str(info.value)


def test_not_a_shard(tmp_path: Path) -> None:
    with pytest.raises(ShardError, match="not a demo shard"):
        load_shard(tmp_path)


# ----------------------------------------------------------------------------- several shards


def test_load_shards_concatenates(lka_shard: Path, tmp_path: Path) -> None:
    other = generate_shard(tmp_path / "other", env_id_or_scenario="lka", env_kwargs={"max_steps": 5},
                           episodes=2, seed=100, policy=SteerBack)
    a, b = load_shard(lka_shard), load_shard(other)
    both = load_shards([lka_shard, other], n_actions=31)
    assert len(both) == len(a) + len(b)
    np.testing.assert_array_equal(both.observations, np.concatenate([a.observations, b.observations]))
    np.testing.assert_array_equal(both.episode_ids, np.concatenate([a.episode_ids, b.episode_ids + 4]))
    meta = both.metadata
    assert meta["episodes"] == 6 and meta["steps"] == len(both) and meta["env_kwargs"] is None
    assert meta["seeds"] == [7, 8, 9, 10, 100, 101] and len(meta["shards"]) == 2
    assert both.sha256 == transition_sha256(
        both.observations, both.actions, both.rewards, both.next_observations,
        both.terminations, both.truncations, both.episode_ids)


def test_load_shards_refuses_disagreeing_shards(lka_shard: Path, tmp_path: Path) -> None:
    stack = generate_shard(tmp_path / "stack", env_id_or_scenario="laneshift-test/Stack-v0",
                           env_kwargs={}, episodes=1, seed=0, policy=_cycle_policy)
    with pytest.raises(ShardError, match=rf"demo shard {stack}: env_id"):
        load_shards([lka_shard, stack])


# ----------------------------------------------------------------------------- writing


def _episode(actions):
    n = len(actions)
    return {"observations": np.zeros((n + 1, 6), np.float32), "actions": actions,
            "rewards": np.zeros(n), "terminations": [False] * n, "truncations": [True] * n}


def test_write_refuses_bad_input(tmp_path: Path) -> None:
    common = dict(env_id=LKA, env_kwargs={}, seeds=[None])
    with pytest.raises(ValueError, match=r"episode 0: actions outside \[0, 31\)"):
        write_shard(tmp_path / "a", [_episode([3, 31])], recorded_by="human", **common)
    with pytest.raises(ValueError, match="recorded_by"):
        write_shard(tmp_path / "a", [_episode([3])], recorded_by="robot", **common)
    bad_obs = _episode([1]) | {"observations": np.zeros((2, 7), np.float32)}
    with pytest.raises(ValueError, match=r"episode 0: observations shape \(2, 7\)"):
        write_shard(tmp_path / "a", [bad_obs], recorded_by="human", **common)
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_write_refuses_to_overwrite(lka_shard: Path) -> None:
    with pytest.raises(FileExistsError):
        write_shard(lka_shard, [_episode([1])], env_id=LKA, env_kwargs={}, recorded_by="human",
                    seeds=[0])


def test_human_shard_keeps_the_given_actions(tmp_path: Path) -> None:
    path = write_shard(tmp_path / "h", [_episode([0, 30, 15]), _episode([2])], env_id=LKA,
                       env_kwargs={}, recorded_by="human", seeds=[None, 5])
    shard = load_shard(path)
    assert shard.actions.tolist() == [0, 30, 15, 2] and shard.episode_ids.tolist() == [0, 0, 0, 1]
    assert shard.metadata["recorded_by"] == "human" and shard.metadata["seeds"] == [None, 5]
    assert shard.metadata["survival_rate"] is None  # no infos given: unknown, not invented


def test_write_into_an_existing_empty_directory(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    path = write_shard(tmp_path / "empty", [_episode([1, 2])], env_id=LKA, env_kwargs={},
                       recorded_by="human", seeds=[0])
    assert load_shard(path).actions.tolist() == [1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"]  # no staging left over


def test_extra_metadata_cannot_override_core_fields(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="must not override sha256"):
        write_shard(tmp_path / "x", [_episode([1])], env_id=LKA, env_kwargs={},
                    recorded_by="human", seeds=[0], extra_metadata={"sha256": "0" * 64})


def test_plain_minari_reads_frame_stack_shards(tmp_path: Path) -> None:
    import minari

    path = generate_shard(tmp_path / "s", env_id_or_scenario="laneshift-test/Stack-v0",
                          env_kwargs={}, episodes=2, seed=4, policy=_cycle_policy)
    shard = load_shard(path)
    dataset = minari.MinariDataset(dataset_data_dir(path))
    assert dataset.observation_space.shape == (12, 10)  # the newest frame of each stack
    for episode in dataset.iterate_episodes():
        rows = shard.episode_ids == episode.id
        np.testing.assert_array_equal(episode.observations[:-1], shard.observations[rows][:, -1])
        with h5py.File(dataset_data_dir(path) / "main_data.hdf5") as f:
            prefix = f[f"episode_{episode.id}/laneshift_stack_prefix"][()]
        np.testing.assert_array_equal(rebuild_frame_stacks(prefix, episode.observations)[:-1],
                                      shard.observations[rows])
