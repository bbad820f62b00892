"""Write demonstration episodes as a demo shard (a Minari hdf5 dataset, see :mod:`.shard`).

Minari's ``DataCollector`` needs jax, so the episodes are handed to Minari as ready-made
``EpisodeBuffer`` objects through ``minari.create_dataset_from_buffers``, with
``MINARI_DATASETS_PATH`` pointed at a staging directory that is then renamed to the output
directory: nothing is ever written to ``~/.minari`` and a failed write leaves no half shard.

Each shard gets its own Minari dataset id (:func:`laneshift.demos.shard.shard_dataset_id`),
the env infos that matter per step (``infos/<key>``, :data:`RECORDED_INFO_KEYS`) and an env
spec whose entry point is an importable ``module:Class``, so ``gymnasium.make(spec)`` (Minari's
``recover_environment``) rebuilds the env in a fresh process.

Imports: numpy, gymnasium, minari and h5py (both lazily, when writing), the demos package.

Example::

    >>> import gymnasium as gym
    >>> env = gym.make("CartPole-v1")
    >>> obs, _ = env.reset(seed=0)
    >>> nxt, reward, term, trunc, _ = env.step(0)
    >>> episode = {"observations": [obs, nxt], "actions": [0], "rewards": [reward],
    ...            "terminations": [term], "truncations": [trunc]}
    >>> write_shard("/tmp/cartpole-demo", [episode], env_id="CartPole-v1", env_kwargs={},
    ...             recorded_by="scripted", seeds=[0])                  # doctest: +SKIP
    PosixPath('/tmp/cartpole-demo')

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import json
import os
import shutil
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from laneshift.demos.checksum import SHA256_SCHEME, episodes_sha256
from laneshift.demos.envsupport import gymnasium_make_id, make_env
from laneshift.demos.framestack import split_frame_stacks
from laneshift.demos.outcomes import episode_outcome, outcome_rates
from laneshift.demos.shard import (
    FORMAT,
    FORMAT_VERSION,
    PREFIX_DATASET,
    recorder_kind,
    shard_dataset_id,
)

# Per-step env infos stored with the episodes (Minari's ``infos`` group, [T+1] each: the reset
# info, then one per step). The outcome flags the paper's rates come from, where the car is
# (lane, target lane, speed) and, for LKA, the errors and steering. A key is stored when every
# info of every episode has it as a scalar; the rest of the info (e.g. the nested reward terms)
# is not: rewards are stored anyway and the terms can be recomputed.
RECORDED_INFO_KEYS = ("crashed", "collided", "offroad", "on_target_lane", "lane_index",
                      "target_lane", "speed", "e1", "e2", "steering")


@contextlib.contextmanager
def _minari_root(root: Path) -> Iterator[None]:
    """Point Minari at ``root`` for the duration (never the user's ~/.minari). Not thread-safe."""
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def check_out_dir(out_dir: str | os.PathLike) -> Path:
    """The absolute shard path; FileExistsError unless it is absent or an empty directory.

    Call it before recording so nobody drives for an hour into a path that cannot be written.
    """
    out = Path(out_dir).absolute()
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FileExistsError(f"{out} exists and is not empty: refusing to overwrite it")
    return out


def _jsonable(value: Any, what: str) -> Any:
    try:
        return json.loads(json.dumps(value, default=_json_default))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} must be JSON-serialisable: {exc}") from exc


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _episode_arrays(
    index: int, episode: Mapping[str, Any], obs_space: gym.spaces.Box, n_actions: int
) -> dict[str, np.ndarray]:
    """Validate one episode dict and return its arrays in storage dtypes."""
    where = f"episode {index}"
    missing = [k for k in ("observations", "actions", "rewards", "terminations", "truncations")
               if k not in episode]
    if missing:
        raise ValueError(f"{where}: missing {', '.join(missing)}")
    raw_obs = np.asarray(episode["observations"])
    actions = np.asarray(episode["actions"])
    steps = len(actions)
    if steps == 0:
        raise ValueError(f"{where}: has no steps")
    if raw_obs.shape != (steps + 1, *obs_space.shape):
        raise ValueError(
            f"{where}: observations shape {raw_obs.shape} != ({steps + 1}, *{obs_space.shape}) "
            "(the reset observation followed by one per step)"
        )
    obs = raw_obs.astype(obs_space.dtype, copy=False)
    if obs.dtype != raw_obs.dtype and not np.array_equal(obs, raw_obs):
        raise ValueError(f"{where}: observations {raw_obs.dtype} do not fit {obs_space.dtype}")
    if actions.ndim != 1 or not (
        np.issubdtype(actions.dtype, np.integer)
        or np.array_equal(actions, np.round(actions))
    ):
        raise ValueError(f"{where}: actions must be a 1-D sequence of integers")
    actions = actions.astype(np.int64)
    if actions.min() < 0 or actions.max() >= n_actions:
        raise ValueError(f"{where}: actions outside [0, {n_actions})")
    arrays = {"observations": obs, "actions": actions}
    for key, dtype in (("rewards", np.float64), ("terminations", bool), ("truncations", bool)):
        value = np.asarray(episode[key], dtype=dtype)
        if value.shape != (steps,):
            raise ValueError(f"{where}: {key} shape {value.shape} != ({steps},)")
        arrays[key] = value
    if not np.all(np.isfinite(arrays["rewards"])):
        raise ValueError(f"{where}: rewards must be finite")
    return arrays


def _env_spec_json(env: gym.Env, env_id: str, env_kwargs: Mapping[str, Any]) -> str | None:
    """The env's spec as JSON for ``gymnasium.make(EnvSpec.from_json(...))`` / Minari's
    ``recover_environment``; None when it cannot be rebuilt elsewhere.

    The entry point must be an importable ``"module:Class"`` string (laneshift's are, e.g.
    ``laneshift.actors.envs.lane_change:StraightLaneChangeEnv``): gymnasium imports it itself,
    so a fresh process needs no registration. ``render_mode`` is dropped (the data does not
    depend on it; a recorder's ``rgb_array`` would only slow the rebuilt env down).
    """
    spec = env.spec
    if spec is None:  # an env built without gym.make: take the registered spec + the kwargs
        try:
            spec = dataclasses.replace(gym.spec(env_id), kwargs=dict(env_kwargs))
        except (gym.error.Error, ImportError):
            return None
    if not isinstance(spec.entry_point, str):  # a callable cannot be serialised or imported
        return None
    kwargs = {k: v for k, v in spec.kwargs.items() if k != "render_mode"}
    try:
        return dataclasses.replace(spec, kwargs=kwargs).to_json()
    except (TypeError, ValueError):  # kwargs that are not JSON
        return None


def _info_scalar(value: Any) -> bool | int | float | None:
    """A plain bool / int / float for an info value that is one, else None."""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value.item()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, (bool, int, float)):
        return value
    return None


def _episode_infos(episodes: Sequence[Mapping[str, Any]],
                   arrays: Sequence[Mapping[str, np.ndarray]]) -> list[dict[str, np.ndarray]] | None:
    """Per-episode ``{key: [T+1] array}`` of the :data:`RECORDED_INFO_KEYS` every info has.

    None (nothing stored) unless every episode has ``infos`` with one dict per observation
    (Minari's convention: the reset info, then one per step) and at least one key qualifies.
    """
    all_infos = [ep.get("infos") for ep in episodes]
    if any(infos is None or len(infos) != len(a["observations"])
           for infos, a in zip(all_infos, arrays)):
        return None
    keys = []
    for key in RECORDED_INFO_KEYS:
        values = [_info_scalar(info.get(key)) if isinstance(info, Mapping) else None
                  for infos in all_infos for info in infos]
        if all(v is not None for v in values):
            # One dtype per key for the whole shard: bool, else int64, else float64.
            if all(isinstance(v, bool) for v in values):
                keys.append((key, np.dtype(bool)))
            elif all(isinstance(v, int) and not isinstance(v, bool) for v in values):
                keys.append((key, np.dtype(np.int64)))
            else:
                keys.append((key, np.dtype(np.float64)))
    if not keys:
        return None
    return [{key: np.asarray([_info_scalar(info[key]) for info in infos], dtype=dtype)
             for key, dtype in keys} for infos in all_infos]


def _observation_name(env_kwargs: Mapping[str, Any], obs_space: gym.spaces.Box) -> str:
    """The observation type: the ``observation`` env kwarg, else what the space looks like."""
    if "observation" in env_kwargs:
        return str(env_kwargs["observation"])
    image_like = obs_space.dtype == np.uint8 and len(obs_space.shape) >= 2
    return "grayscale" if image_like else "vector"


def write_shard(
    out_dir: str | os.PathLike,
    episodes: list[dict],
    *,
    env_id: str,
    env_kwargs: dict,
    recorded_by: str,
    seeds: Sequence[int | None],
    env: gym.Env | None = None,
    extra_metadata: Mapping[str, Any] | None = None,
    dataset_id: str | None = None,
) -> Path:
    """Write ``episodes`` as a demo shard: ``out_dir`` becomes a Minari root with one dataset.

    Each episode is a dict with ``observations`` ([T+1, *obs_shape]: the reset observation then
    one per step), ``actions``, ``rewards``, ``terminations``, ``truncations`` ([T] each) and
    optionally ``infos`` (the info dicts; the last one gives the episode's outcome: crash /
    on target lane; with one per observation, [T+1], the :data:`RECORDED_INFO_KEYS` they all
    have are stored per step). ``recorded_by`` is ``human``, ``scripted`` or a human-like
    stand-in's label (``laneshift.tools.demos.humanlike.stand_in_label``). ``seeds`` holds each
    episode's reset seed (None if unseeded). ``env`` is the env the episodes came from (its
    spaces and spec are recorded); when omitted it is built from ``env_id`` + ``env_kwargs``.
    ``dataset_id`` is the Minari id (default :func:`~laneshift.demos.shard.shard_dataset_id`
    of the env, the recorder and ``out_dir``'s name). ``out_dir`` must not exist (an empty
    directory is fine); it is written under a temporary sibling and renamed, so a failed write
    leaves nothing.

    Example::

        >>> path = write_shard("runs/demo-cartpole", episodes, env_id="CartPole-v1",
        ...     env_kwargs={}, recorded_by="scripted", seeds=[0, 1])   # doctest: +SKIP
    """
    import minari  # heavy import, only needed here

    from minari.dataset.minari_dataset import parse_dataset_id

    out = check_out_dir(out_dir)
    kind = recorder_kind(recorded_by)  # ValueError for anything else
    if dataset_id is None:
        dataset_id = shard_dataset_id(env_id, recorded_by, out.name)
    try:
        parse_dataset_id(dataset_id)
    except (ValueError, TypeError) as exc:  # int(None): an id without "-vN"
        raise ValueError(f"dataset_id {dataset_id!r} is not a Minari id "
                         "((namespace/)name-vN)") from exc
    if not episodes:
        raise ValueError("no episodes to write")
    seeds = [None if s is None else int(s) for s in seeds]
    if len(seeds) != len(episodes):
        raise ValueError(f"{len(seeds)} seeds for {len(episodes)} episodes (one per episode)")
    env_kwargs = _jsonable(dict(env_kwargs), "env_kwargs")
    extra = _jsonable(dict(extra_metadata or {}), "extra_metadata")

    own_env = env is None
    if env is None:
        env = make_env(env_id, env_kwargs)
    try:
        obs_space, action_space = env.observation_space, env.action_space
        if not isinstance(action_space, gym.spaces.Discrete):
            raise ValueError(f"demo shards need a Discrete action space, {env_id} has {action_space}")
        if not isinstance(obs_space, gym.spaces.Box):
            raise ValueError(f"demo shards need a Box observation space, {env_id} has {obs_space}")
        n_actions = int(action_space.n)
        spec_json = _env_spec_json(env, env_id, env_kwargs)
    finally:
        if own_env:
            env.close()

    arrays = [_episode_arrays(i, ep, obs_space, n_actions) for i, ep in enumerate(episodes)]
    obs_shape = tuple(int(n) for n in obs_space.shape)
    sha = episodes_sha256(
        [a["observations"] for a in arrays], [a["actions"] for a in arrays],
        [a["rewards"] for a in arrays], [a["terminations"] for a in arrays],
        [a["truncations"] for a in arrays], obs_space.dtype,
    )

    # Frame-stack encoding when every episode is an exact shifting stack (grayscale obs).
    splits = [split_frame_stacks(a["observations"]) for a in arrays]
    frame_stack = all(s is not None for s in splits)
    if frame_stack:
        stored_space = gym.spaces.Box(
            low=obs_space.low[-1], high=obs_space.high[-1], dtype=obs_space.dtype
        )
        stored_obs = [s[1] for s in splits]
    else:
        stored_space = obs_space
        stored_obs = [a["observations"] for a in arrays]

    from minari.data_collector import EpisodeBuffer

    infos = _episode_infos(episodes, arrays)
    buffers = [
        EpisodeBuffer(
            seed=seed, observations=obs, actions=a["actions"], rewards=a["rewards"],
            terminations=a["terminations"], truncations=a["truncations"],
            infos=None if infos is None else infos[index],
        )
        for index, (seed, obs, a) in enumerate(zip(seeds, stored_obs, arrays))
    ]
    outcomes = [episode_outcome((ep.get("infos") or [None])[-1]) for ep in episodes]
    steps = int(sum(len(a["actions"]) for a in arrays))
    meta: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "dataset_id": dataset_id,
        "env_id": env_id,
        "env_kwargs": env_kwargs,
        # What gymnasium.make takes in a fresh process (the module prefix registers the id).
        "gymnasium_id": gymnasium_make_id(env_id),
        "observation": _observation_name(env_kwargs, obs_space),
        "n_actions": n_actions,
        "obs_shape": list(obs_shape),
        "obs_dtype": np.dtype(obs_space.dtype).name,
        "obs_encoding": "frame_stack" if frame_stack else "full",
        "recorded_by": recorded_by,
        "seeds": seeds,
        "info_keys": [] if infos is None else sorted(infos[0]),
        "sha256": sha,
        "sha256_scheme": SHA256_SCHEME,
        "episodes": len(episodes),
        "steps": steps,
        **outcome_rates(outcomes),
        "outcomes": outcomes,
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    clash = sorted(set(extra) & set(meta))
    if clash:
        raise ValueError(f"extra_metadata must not override {', '.join(clash)}")
    meta.update(extra)

    staging_root = out.parent / f".{out.name}.partial-{os.getpid()}"
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(staging_root, ignore_errors=True)
    try:
        with _minari_root(staging_root), warnings.catch_warnings():
            # Minari nags about optional metadata (author e-mail, code permalink, ...).
            warnings.filterwarnings("ignore", category=UserWarning, module=r"minari(\.|$)")
            dataset = minari.create_dataset_from_buffers(
                dataset_id=dataset_id,
                buffer=buffers,
                env=None,  # passing the env id would make Minari build a second env
                observation_space=stored_space,
                action_space=action_space,
                algorithm_name=f"laneshift demonstrations ({kind})",
                author=f"laneshift {kind} demonstrator",
                description=(
                    f"laneshift demo shard: {len(episodes)} episodes recorded by {recorded_by} "
                    f"on {env_id} "
                    f"with {env_kwargs}; observations stored as {meta['obs_encoding']}"
                ),
                jpeg_encoding=False,  # lossless: JPEG would change the frames
            )
        storage = dataset.storage
        if frame_stack:
            import h5py

            with h5py.File(storage.data_path / "main_data.hdf5", "a") as file:
                for index, (prefix, _frames) in enumerate(splits):
                    file[f"episode_{index}"].create_dataset(PREFIX_DATASET, data=prefix)
        update: dict[str, Any] = {"laneshift": meta, "dataset_size": storage.get_size()}
        if spec_json is not None:
            update["env_spec"] = spec_json  # lets minari's recover_environment() rebuild it
        storage.update_metadata(update)
        if out.exists():
            out.rmdir()  # empty (checked above): replaced by the staging directory
        staging_root.rename(out)  # the whole Minari root becomes DIR in one step
    finally:
        shutil.rmtree(staging_root, ignore_errors=True)
    return out
