"""A run's directory before the launch: one launcher per run dir (``RunDirLock``), a run dir
that already holds a run refused unless ``--resume`` or ``--overwrite`` (``prepare_run_dir``),
room kept for the run's end records (``SpaceReserve``), and the default scripted demo shard made
once under ``<run dir>/../demos/`` (``ensure_demo_shard``).

Room: deploy, the wiring. May import: the contract, the demo tools, the env (for the demo shard's
size and name).
"""

from __future__ import annotations

import dataclasses
import fcntl
import json
import math
import os
import shutil
from pathlib import Path
from typing import TextIO

from laneshift.config import RunConfig

from .errors import LaunchError


class RunDirLock:
    """One launcher per run dir (``<run dir>/.lock``, released when the process ends, even by kill -9)."""

    def __init__(self, run_dir: Path):
        self.path = run_dir / ".lock"
        self._fd: int | None = None

    def acquire(self) -> "RunDirLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise LaunchError(f"run dir {self.path.parent} is in use by another `laneshift train` (pid {holder})") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class SpaceReserve:
    """Room kept in the run dir for the run's end records (``summary.json``, the replay's final
    stats): a file of ``size`` bytes written at the launch and removed just before they are
    written, so that a run dir that fills up during the run (checkpoints, logs, metrics: each
    failure counted) still gets the run's accounting. Why: on a full disk the summary alone was
    printed and the counts of what was stored and lost were nowhere on disk (``laneshift chaos
    --faults disk-full``). A reserve that cannot be written (a disk already full) is said in one
    line; the run goes on without it."""

    NAME = ".space-reserve"

    def __init__(self, run_dir: Path, size: int = 1 << 20):
        self.path, self.size = run_dir / self.NAME, size

    def hold(self, out: TextIO) -> bool:
        try:
            # Written, not truncated to size (a hole holds no blocks), and random, so that a
            # compressing or deduplicating filesystem keeps the room too.
            with self.path.open("wb") as f:
                f.write(os.urandom(self.size))
            return True
        except OSError as exc:
            self.release()
            print(f"train: no room kept for the end records in {self.path.parent} ({exc})", file=out, flush=True)
            return False

    def release(self) -> None:
        try:
            self.path.unlink()
        except OSError:  # gone already, or a read-only run dir (the file stays, harmless)
            pass


#: What a run leaves in its run dir that a new run must not silently reuse (and RUN_STATE_GLOBS:
#: each replay shard's checkpoint, write-ahead log and stats; a stale log would be replayed).
RUN_STATE = ("config.yaml", "replay_checkpoint", "checkpoints", "summary.json", "replay_stats.json",
             "metrics.jsonl", "tb", "logs")
RUN_STATE_GLOBS = ("replay_checkpoint*", "replay_stats*.json")


def prepare_run_dir(run_dir: Path, resume: bool, overwrite: bool, out: TextIO) -> None:
    used = (run_dir / "config.yaml").exists()
    if used and not (resume or overwrite):
        raise LaunchError(f"run dir {run_dir} already holds a run: `--resume {run_dir}` continues it, "
                          f"--overwrite starts it over, or choose another --run-dir")
    if resume and not used:
        raise LaunchError(f"--resume {run_dir}: no run there (no config.yaml)")
    if overwrite and used:
        print(f"train: --overwrite: removing the previous run's state in {run_dir}", file=out, flush=True)
        paths = [run_dir / name for name in RUN_STATE]
        paths += [p for pattern in RUN_STATE_GLOBS for p in sorted(run_dir.glob(pattern)) if p not in paths]
        for path in paths:
            shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)


# ---------------------------------------------------------------------------- demo shard


def _default_demo_episodes(cfg: RunConfig) -> int:
    """Scripted episodes for the default shard: ``train.demo_episodes``, else enough for
    retention's demo region (or 2,000 transitions for rehearsal), at least 20."""
    from laneshift.actors.envs import make as make_env

    if cfg.train.demo_episodes:
        return cfg.train.demo_episodes
    need = cfg.replay.capacity * cfg.replay.demo_ratio if cfg.replay.retains_demos else 2_000
    probe = make_env(cfg.env)
    horizon = getattr(probe.unwrapped, "max_steps", None) or 100
    probe.close()
    return max(20, math.ceil(1.3 * need / horizon))


def default_demo_dir(cfg: RunConfig, episodes: int) -> Path:
    """Where the default scripted shard lives (shared by runs; its size and the driver's version
    are in the name, so a run that needs more demos, or a newer driver's, gets a new shard instead
    of a refusal or stale demos)."""
    from laneshift.actors.envs.demonstrator import ScriptedDriver
    from laneshift.actors.envs import spec_of

    env = cfg.env
    # The observation's shape is in the name: a layout change makes a new shard, not a refusal.
    shape = "x".join(str(d) for d in spec_of(env).schema.obs_shape)
    if env.frame_supersample != 1:  # the frames are drawn otherwise: another shard
        shape += f"-ss{env.frame_supersample}"
    if env.frame_interval != 1:  # the stacked frames lie further apart in time: another shard
        shape += f"-fi{env.frame_interval}"
    if env.frame_centering != 0.5:  # the ego elsewhere in the frame: another shard
        shape += f"-c{env.frame_centering:g}"
    if env.frame_scale != 2.0:  # another scale: another shard
        shape += f"-px{env.frame_scale:g}"
    scenario = env.scenario.replace('/', '_') + (f"-{env.road}" if env.road else "")  # allroads pinned to one road
    shield = "-shield" if env.shield else ""  # the driver drove behind the shield
    # Episodes started outside the target lane only are other demonstrations: another shard.
    start = "" if env.initial_lane == "random" else f"-{env.initial_lane}"
    start += "-achieved" if cfg.train.demo_achieved_only else ""  # the driver's successes only: other demos
    name = (f"{scenario}-{env.observation}{shape}-p{env.reward_preset}{shield}{start}"
            f"-scripted-v{ScriptedDriver.VERSION}-{episodes}ep")
    return Path(cfg.train.run_dir).resolve().parent / "demos" / name


def ensure_demo_shard(cfg: RunConfig, out: TextIO) -> RunConfig:
    """Demo modes without a shard get the scripted demonstrator's, generated once if absent."""
    if cfg.replay.demo_mode == "none" or cfg.replay.demo_paths:
        return cfg
    episodes = _default_demo_episodes(cfg)
    path = default_demo_dir(cfg, episodes)
    if not any(path.glob("**/metadata.json")):
        from laneshift.tools.demos.generate import generate_shard

        print(f"train: generating the default demo shard ({episodes} scripted episodes) in {path}", file=out, flush=True)
        generate_shard(path, env_id_or_scenario=cfg.env.scenario, env_kwargs=cfg.env.env_kwargs(),
                       episodes=episodes, seed=cfg.train.seed + 10_000,
                       achieved_only=cfg.train.demo_achieved_only)
    return cfg.replace(replay=dataclasses.replace(cfg.replay, demo_paths=(str(path),)))
