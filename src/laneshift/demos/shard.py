"""Demo shards: human / scripted demonstrations stored as a Minari dataset (hdf5 backend).

A shard is one directory ``DIR`` that is a Minari datasets root holding one dataset. Its id is
the shard's own (:func:`shard_dataset_id`): ``laneshift/<scenario>-<driver>-<DIR's name>-v0``,
e.g. ``laneshift/straight-scripted-straight-v0`` (shards written before per-shard ids hold
``laneshift-demos-v0``, :data:`LEGACY_DATASET_ID`, and still load)::

    DIR/laneshift/<name>-v0/data/metadata.json   Minari metadata + a "laneshift" section
    DIR/laneshift/<name>-v0/data/main_data.hdf5  episode_0 .. episode_{E-1}: observations
                               [T+1,..], actions [T], rewards [T], terminations [T],
                               truncations [T], infos/<key> [T+1]
                               (+ laneshift_stack_prefix [S-1, W, H] for frame-stack encoding)

so plain Minari reads it with ::

    MINARI_DATASETS_PATH=DIR python -c "import minari; print(minari.load_dataset('laneshift/...-v0'))"
    # or, without the variable: minari.MinariDataset(dataset_data_dir(DIR))

The replay server reads it with :func:`load_shard` / :func:`load_shards`, which rebuild flat
transition arrays (:class:`DemoShard`), verify the sha256 recorded at write time and check the
shard against the run's env.

The checksum covers the flat transition arrays, not the file encoding (scheme in
:mod:`laneshift.demos.checksum`). Shards are written by :func:`laneshift.tools.demos.writer.write_shard`.

Imports: numpy, h5py (lazily) and the demos package's own helpers; never minari (reading needs
only the files).

Example::

    >>> env = make_env("straight")                                          # doctest: +SKIP
    >>> shard = load_shard("runs/demos/straight", env_id="laneshift/StraightLaneChange-v0",
    ...                    obs_shape=env.observation_space.shape,
    ...                    obs_dtype=env.observation_space.dtype, n_actions=9)  # doctest: +SKIP
    >>> len(shard), shard.sha256[:12]                                           # doctest: +SKIP

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .checksum import SHA256_SCHEME, arrays_sha256, episodes_sha256
from .envsupport import resolve_env_id, scenarios
from .framestack import rebuild_frame_stacks
from .outcomes import outcome_rates

FORMAT = "laneshift-demos"
FORMAT_VERSION = 1
RECORDERS = ("human", "scripted")
# recorded_by of a human-like stand-in starts with this (the full label names its parameters and
# says "not a person": laneshift.tools.demos.humanlike.stand_in_label).
STAND_IN_PREFIX = "human-like stand-in"
PREFIX_DATASET = "laneshift_stack_prefix"  # extra hdf5 dataset per episode (Minari ignores it)
# The Minari id every shard had before shards got their own (shard_dataset_id); such shards
# still load. Minari ids need a "-vN" suffix, so the shard directory is the datasets root
# (MINARI_DATASETS_PATH) rather than the dataset itself.
LEGACY_DATASET_ID = "laneshift-demos-v0"
DATASET_ID = LEGACY_DATASET_ID  # the old name, kept for code that imported it
DATASET_NAMESPACE = "laneshift"  # Minari namespace of the per-shard ids


def recorder_kind(recorded_by: str) -> str:
    """``human``, ``scripted`` or ``human-like`` for a ``recorded_by`` value, else ValueError.

    Example::

        >>> recorder_kind("human-like stand-in (scripted driver + ...); not a person")
        'human-like'
    """
    if recorded_by in RECORDERS:
        return recorded_by
    if isinstance(recorded_by, str) and recorded_by.startswith(STAND_IN_PREFIX):
        return "human-like"
    raise ValueError(f"recorded_by must be one of {RECORDERS} or a '{STAND_IN_PREFIX} ...' "
                     f"label, not {recorded_by!r}")


def _id_part(text: str) -> str:
    """``text`` reduced to what a Minari dataset name allows (ASCII letters, digits, _ and -)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_-") or "x"


def shard_dataset_id(env_id: str, recorded_by: str, out_name: str) -> str:
    """The Minari id of a shard: ``laneshift/<scenario>-<driver>-<out_name>-v0``.

    ``scenario`` is laneshift's short name for ``env_id`` (else the id, sanitised), ``driver``
    the recorder kind (:func:`recorder_kind`), ``out_name`` the shard directory's name. Each
    part keeps only ``[A-Za-z0-9_-]``, so the id fits Minari's ``(namespace/)name-vN`` rule.

    Example::

        >>> shard_dataset_id("CartPole-v1", "scripted", "my demos")
        'laneshift/CartPole-v1-scripted-my_demos-v0'
    """
    names = {env: name for name, env in scenarios().items()}
    scenario = names.get(env_id, env_id)
    return (f"{DATASET_NAMESPACE}/{_id_part(scenario)}-{recorder_kind(recorded_by)}-"
            f"{_id_part(out_name)}-v0")


class ShardError(ValueError):
    """A demo shard is unreadable, corrupted or does not fit the run; the message says which."""


@dataclass(frozen=True, eq=False)  # eq=False: element-wise array equality has no single truth value
class DemoShard:
    """Flat transitions of one or more demo shards, ready to be put in a replay buffer.

    Example::

        >>> shard = load_shard("runs/demos/straight")           # doctest: +SKIP
        >>> shard.observations.shape, shard.actions.dtype        # doctest: +SKIP
        ((15000, 67), dtype('int64'))
    """

    observations: np.ndarray  # [N, *obs_shape], env obs dtype
    actions: np.ndarray  # [N] int64
    rewards: np.ndarray  # [N] float32
    next_observations: np.ndarray  # [N, *obs_shape]
    terminations: np.ndarray  # [N] bool
    truncations: np.ndarray  # [N] bool
    episode_ids: np.ndarray  # [N] int32
    metadata: dict  # env_id, env_kwargs, observation, n_actions, obs_shape, obs_dtype,
    # recorded_by, seeds, sha256, episodes, steps (+ survival_rate, achievement_rate, ...)

    @property
    def sha256(self) -> str:
        """Checksum of the transition arrays (scheme in :mod:`laneshift.demos.checksum`)."""
        return self.metadata["sha256"]

    def __len__(self) -> int:
        return len(self.actions)


def assemble_transitions(
    obs_sequences: Sequence[np.ndarray],
    actions: Sequence[np.ndarray],
    rewards: Sequence[np.ndarray],
    terminations: Sequence[np.ndarray],
    truncations: Sequence[np.ndarray],
    obs_shape: tuple[int, ...],
    obs_dtype: np.dtype,
) -> dict[str, np.ndarray]:
    """Per-episode sequences ([T+1] observations, [T] the rest) -> flat DemoShard arrays."""
    lengths = [len(a) for a in actions]
    total = int(sum(lengths))
    out = {
        "observations": np.empty((total, *obs_shape), obs_dtype),
        "next_observations": np.empty((total, *obs_shape), obs_dtype),
        "actions": np.empty(total, np.int64),
        "rewards": np.empty(total, np.float32),
        "terminations": np.empty(total, bool),
        "truncations": np.empty(total, bool),
        "episode_ids": np.empty(total, np.int32),
    }
    start = 0
    for episode, steps in enumerate(lengths):
        end = start + steps
        out["observations"][start:end] = obs_sequences[episode][:-1]
        out["next_observations"][start:end] = obs_sequences[episode][1:]
        out["actions"][start:end] = actions[episode]
        out["rewards"][start:end] = rewards[episode]
        out["terminations"][start:end] = terminations[episode]
        out["truncations"][start:end] = truncations[episode]
        out["episode_ids"][start:end] = episode
        start = end
    return out


def dataset_data_dir(path: str | os.PathLike) -> Path:
    """The Minari data directory of a shard given as ``DIR``, its dataset directory or ``data``.

    ``DIR`` holds one dataset: ``DIR/laneshift/<name>-v0`` (per-shard id) or, for shards written
    before per-shard ids, ``DIR/laneshift-demos-v0``.

    Example::

        >>> dataset_data_dir("runs/demos/straight")          # doctest: +SKIP
        PosixPath('runs/demos/straight/laneshift/straight-scripted-straight-v0/data')
    """
    path = Path(path)
    for candidate in (path / LEGACY_DATASET_ID / "data", path / "data", path):
        if (candidate / "metadata.json").is_file():
            return candidate
    # A per-shard id: one level of namespace (laneshift/...), or none for ids without one.
    found = sorted({meta.parent for pattern in ("*/*/data/metadata.json", "*/data/metadata.json")
                    for meta in path.glob(pattern)})
    if len(found) == 1:
        return found[0]
    if len(found) > 1:
        names = ", ".join(str(f.parent.relative_to(path)) for f in found)
        raise ShardError(f"demo shard {path}: holds {len(found)} datasets ({names}); "
                         "give the directory of one of them")
    raise ShardError(
        f"demo shard {path}: not a demo shard (no <dataset id>/data/metadata.json in it)"
    )


def _fmt_shape(shape: Sequence[int]) -> str:
    shape = tuple(int(n) for n in shape)
    return f"({shape[0]},)" if len(shape) == 1 else "(" + ",".join(map(str, shape)) + ")"


def _read_metadata(path: Path) -> tuple[Path, dict]:
    data_dir = dataset_data_dir(path)
    meta_file = data_dir / "metadata.json"
    try:
        minari_meta = json.loads(meta_file.read_text())
    except (OSError, ValueError) as exc:
        raise ShardError(f"demo shard {path}: cannot read {meta_file}: {exc}") from exc
    meta = minari_meta.get("laneshift")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ShardError(f"demo shard {path}: {meta_file} has no laneshift demo metadata")
    if meta.get("format_version") != FORMAT_VERSION:
        raise ShardError(
            f"demo shard {path}: format_version {meta.get('format_version')} is not supported "
            f"(this laneshift reads {FORMAT_VERSION})"
        )
    required = ("env_id", "n_actions", "obs_shape", "obs_dtype", "obs_encoding", "sha256",
                "episodes", "steps")
    missing = [k for k in required if k not in meta]
    if missing:
        raise ShardError(f"demo shard {path}: {meta_file} lacks {', '.join(missing)}")
    meta = dict(meta)
    meta["obs_shape"] = tuple(int(n) for n in meta["obs_shape"])
    # Shards of before per-shard ids do not record theirs: Minari's own field has it.
    meta.setdefault("dataset_id", minari_meta.get("dataset_id"))
    if minari_meta.get("total_episodes") != meta["episodes"]:
        raise ShardError(
            f"demo shard {path}: metadata says {meta['episodes']} episodes but Minari "
            f"counts {minari_meta.get('total_episodes')}"
        )
    return data_dir, meta


def read_metadata(path: str | os.PathLike) -> dict:
    """A shard's laneshift metadata without reading (or verifying) its data; ``path`` added.

    Example::

        >>> read_metadata("runs/demos/straight")["episodes"]      # doctest: +SKIP
        50
    """
    _data_dir, meta = _read_metadata(Path(path))
    return {**meta, "path": str(path)}


def _check_expectations(
    where: Path,
    meta: Mapping[str, Any],
    env_id: str | None,
    obs_shape: tuple | None,
    obs_dtype: Any,
    n_actions: int | None,
    against: str = "the run's env",
) -> None:
    if env_id is not None and resolve_env_id(env_id) != meta["env_id"]:
        raise ShardError(
            f"demo shard {where}: env_id {meta['env_id']!r} != {against} "
            f"{resolve_env_id(env_id)!r}"
        )
    if obs_shape is not None and tuple(int(n) for n in obs_shape) != meta["obs_shape"]:
        raise ShardError(
            f"demo shard {where}: observation shape {_fmt_shape(meta['obs_shape'])} != "
            f"{against} {_fmt_shape(obs_shape)}"
        )
    if obs_dtype is not None and np.dtype(obs_dtype) != np.dtype(meta["obs_dtype"]):
        raise ShardError(
            f"demo shard {where}: observation dtype {meta['obs_dtype']} != {against} "
            f"{np.dtype(obs_dtype).name}"
        )
    if n_actions is not None and int(n_actions) != int(meta["n_actions"]):
        raise ShardError(
            f"demo shard {where}: {meta['n_actions']} actions != {against} {int(n_actions)}"
        )


@dataclass
class ShardEpisodes:
    """One shard's per-episode sequences as stored (before flattening into a DemoShard)."""

    path: Path
    meta: dict
    observations: list[np.ndarray]  # [T+1, *obs_shape] each (views for frame stacks)
    actions: list[np.ndarray]
    rewards: list[np.ndarray]
    terminations: list[np.ndarray]
    truncations: list[np.ndarray]

    @property
    def steps(self) -> int:
        return int(sum(len(a) for a in self.actions))


def _read_raw(path: Path, expect: Mapping[str, Any]) -> ShardEpisodes:
    import h5py

    data_dir, meta = _read_metadata(path)
    _check_expectations(path, meta, **expect)
    obs_shape, obs_dtype = meta["obs_shape"], np.dtype(meta["obs_dtype"])
    n_actions = int(meta["n_actions"])
    frame_stack = meta["obs_encoding"] == "frame_stack"
    if meta["obs_encoding"] not in ("frame_stack", "full"):
        raise ShardError(f"demo shard {path}: unknown obs_encoding {meta['obs_encoding']!r}")
    h5_file = data_dir / "main_data.hdf5"
    raw = ShardEpisodes(path, meta, [], [], [], [], [])

    def bad(episode: int, field: str, problem: str) -> ShardError:
        return ShardError(f"demo shard {path}: {h5_file.name} episode_{episode}/{field} {problem}")

    try:
        with h5py.File(h5_file, "r") as file:
            for episode in range(meta["episodes"]):
                group = file[f"episode_{episode}"]
                actions = group["actions"][()]
                steps = len(actions)
                if actions.shape != (steps,) or not np.issubdtype(actions.dtype, np.integer):
                    raise bad(episode, "actions", f"has shape {actions.shape} {actions.dtype}")
                if steps and (actions.min() < 0 or actions.max() >= n_actions):
                    raise bad(episode, "actions", f"are outside [0, {n_actions})")
                stored = group["observations"][()]
                if frame_stack:
                    prefix = group[PREFIX_DATASET][()]
                    want_prefix = (obs_shape[0] - 1, *obs_shape[1:])
                    if prefix.shape != want_prefix or prefix.dtype != obs_dtype:
                        raise bad(episode, PREFIX_DATASET,
                                  f"shape {_fmt_shape(prefix.shape)} {prefix.dtype} != "
                                  f"{_fmt_shape(want_prefix)} {obs_dtype}")
                    want = (steps + 1, *obs_shape[1:])
                else:
                    want = (steps + 1, *obs_shape)
                if stored.shape != want or stored.dtype != obs_dtype:
                    raise bad(episode, "observations",
                              f"shape {_fmt_shape(stored.shape)} {stored.dtype} != "
                              f"{_fmt_shape(want)} {obs_dtype} (recorded obs_shape "
                              f"{_fmt_shape(obs_shape)}, {steps} steps)")
                raw.observations.append(
                    rebuild_frame_stacks(prefix, stored) if frame_stack else stored
                )
                raw.actions.append(actions.astype(np.int64))
                for field, target in (("rewards", raw.rewards),
                                      ("terminations", raw.terminations),
                                      ("truncations", raw.truncations)):
                    value = group[field][()]
                    if value.shape != (steps,):
                        raise bad(episode, field, f"shape {value.shape} != ({steps},)")
                    target.append(value)
    except ShardError:
        raise
    except (OSError, KeyError, ValueError) as exc:  # unreadable / truncated / missing datasets
        raise ShardError(f"demo shard {path}: cannot read {h5_file}: {exc}") from exc
    if raw.steps != meta["steps"]:
        raise ShardError(
            f"demo shard {path}: {raw.steps} steps in {h5_file.name} != {meta['steps']} in metadata"
        )
    return raw


def _verify(raw: ShardEpisodes) -> None:
    """Recompute the shard's sha256 episode by episode (nothing of the flat size is built)."""
    sha = episodes_sha256(raw.observations, raw.actions, raw.rewards, raw.terminations,
                          raw.truncations, np.dtype(raw.meta["obs_dtype"]))
    if sha != raw.meta["sha256"]:
        raise ShardError(
            f"demo shard {raw.path}: sha256 mismatch: the data hashes to {sha[:16]}... but "
            f"metadata.json records {str(raw.meta['sha256'])[:16]}... (main_data.hdf5 or "
            "metadata.json was changed or corrupted)"
        )


def read_verified(path: str | os.PathLike, **expect: Any) -> ShardEpisodes:
    """One shard's per-episode sequences, checked like :func:`load_shard` but not flattened.

    For tools that need less than the flat transitions (``inspect``): observations stay as
    stored (frame stacks are views over the frames), so memory stays near the file size.
    """
    allowed = {"env_id", "obs_shape", "obs_dtype", "n_actions"}
    unknown = set(expect) - allowed
    if unknown:
        raise TypeError(f"unexpected keyword(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    raw = _read_raw(Path(path), {key: expect.get(key) for key in sorted(allowed)})
    _verify(raw)
    return raw


def load_shard(
    path: str | os.PathLike,
    *,
    env_id: str | None = None,
    obs_shape: tuple | None = None,
    obs_dtype: Any = None,
    n_actions: int | None = None,
) -> DemoShard:
    """Load and verify one demo shard (its directory ``DIR``, see :func:`dataset_data_dir`).

    Checks the sha256 and, when given, that ``env_id`` (id or scenario name), ``obs_shape``,
    ``obs_dtype`` and ``n_actions`` match the run's env; raises :class:`ShardError` naming the
    mismatch otherwise.

    Example::

        >>> shard = load_shard("runs/demos/straight", obs_shape=(25,))   # doctest: +SKIP
    """
    return load_shards([path], env_id=env_id, obs_shape=obs_shape, obs_dtype=obs_dtype,
                       n_actions=n_actions)


def load_shards(paths: Sequence[str | os.PathLike], **expect: Any) -> DemoShard:
    """Load, verify and concatenate several demo shards (same keyword checks as load_shard).

    Episode ids are renumbered to stay unique (shard k's ids follow shard k-1's). The combined
    metadata keeps env_id, n_actions, obs_shape, obs_dtype, observation; sums episodes and
    steps; concatenates seeds and outcomes; ``recorded_by`` / ``env_kwargs`` are the shards'
    common value, or ``"mixed"`` / None when they differ; ``sha256`` is recomputed over the
    concatenated arrays; ``shards`` lists each shard's own metadata (with its path).

    Example::

        >>> demos = load_shards(["runs/demos/a", "runs/demos/b"], n_actions=9)  # doctest: +SKIP
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise ShardError("no demo shard paths given")
    raws = [read_verified(p, **expect) for p in paths]
    first = raws[0].meta
    for raw in raws[1:]:  # shards must agree with each other, not only with the run
        _check_expectations(raw.path, raw.meta, env_id=first["env_id"],
                            obs_shape=first["obs_shape"], obs_dtype=first["obs_dtype"],
                            n_actions=first["n_actions"], against=f"shard {raws[0].path}")

    arrays = assemble_transitions(
        [o for r in raws for o in r.observations], [a for r in raws for a in r.actions],
        [x for r in raws for x in r.rewards], [x for r in raws for x in r.terminations],
        [x for r in raws for x in r.truncations], first["obs_shape"], np.dtype(first["obs_dtype"]),
    )

    shard_metas = [{**r.meta, "path": str(r.path)} for r in raws]
    if len(raws) == 1:
        metadata = shard_metas[0]
    else:
        def common(key: str, differ: Any) -> Any:
            values = [m.get(key) for m in shard_metas]
            return values[0] if all(v == values[0] for v in values) else differ

        outcomes = [o for m in shard_metas for o in m.get("outcomes", [])]
        metadata = {
            "env_id": first["env_id"],
            "env_kwargs": common("env_kwargs", None),
            "observation": common("observation", "mixed"),
            "n_actions": first["n_actions"],
            "obs_shape": first["obs_shape"],
            "obs_dtype": first["obs_dtype"],
            "recorded_by": common("recorded_by", "mixed"),
            "seeds": [s for m in shard_metas for s in m.get("seeds", [])],
            "sha256": arrays_sha256(arrays),
            "sha256_scheme": SHA256_SCHEME,
            "episodes": int(sum(m["episodes"] for m in shard_metas)),
            "steps": int(sum(m["steps"] for m in shard_metas)),
            **outcome_rates(outcomes),
            "outcomes": outcomes,
            "shards": shard_metas,
        }
    return DemoShard(metadata=metadata, **arrays)
