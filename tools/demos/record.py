"""Record human demonstrations: a person drives the env with the keyboard in a pygame window.

The env renders ``rgb_array`` frames (the paper's colours: target lane blue, other lanes
green, off-road black); this module shows them in its own window with a status line and
steps the env at a fixed rate (``fps``, default the env's ``render_fps``). At every step the
arrow keys held - or pressed since the previous step, so a short tap is not lost - choose the
paper action (:mod:`.keys`), and that action is what is stored. P pauses, Backspace discards the
current episode (it restarts with the next seed), Esc / Q / closing the window quits; the
completed episodes are written as a ``recorded_by="human"`` shard.

Works on a real display, under Xvfb, and with ``SDL_VIDEODRIVER=offscreen`` (tests); the
frames come from the env's own renderer, so they are real even where pygame has no screen.
Tests inject key events through ``before_frame``, called before every frame is processed.

Example::

    >>> record_shard("runs/demos/human-straight", env_id_or_scenario="straight",
    ...              env_kwargs={"observation": "grayscale"}, episodes=20, seed=0)  # doctest: +SKIP

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from laneshift.demos.envsupport import make_env, resolve_env_id  # noqa: E402
from .keys import DRIVING_KEYS, N_PAPER_ACTIONS, action_label, control_command, keys_to_action  # noqa: E402
from .writer import check_out_dir, write_shard  # noqa: E402

HELP_TEXT = "arrows: speed +/-, turn left/right   P: pause   Backspace: discard   Esc/Q: quit"


@dataclass
class Recording:
    """What a session produced: completed episodes (write_shard format) and their seeds."""

    episodes: list[dict[str, Any]] = field(default_factory=list)
    seeds: list[int] = field(default_factory=list)
    discarded: int = 0
    quit_early: bool = False


class _Episode:
    """One episode being recorded (kept in Python lists until it completes)."""

    def __init__(self, seed: int, obs: np.ndarray, info: dict) -> None:
        self.seed = seed
        self.observations = [np.array(obs, copy=True)]
        self.actions: list[int] = []
        self.rewards: list[float] = []
        self.terminations: list[bool] = []
        self.truncations: list[bool] = []
        self.infos = [info]

    def add(self, action: int, obs: np.ndarray, reward: float, terminated: bool,
            truncated: bool, info: dict) -> None:
        self.observations.append(np.array(obs, copy=True))  # envs may reuse their obs buffer
        self.actions.append(action)
        self.rewards.append(float(reward))
        self.terminations.append(bool(terminated))
        self.truncations.append(bool(truncated))
        self.infos.append(info)

    def as_dict(self) -> dict[str, Any]:
        return {
            "observations": np.stack(self.observations),
            "actions": np.asarray(self.actions, np.int64),
            "rewards": np.asarray(self.rewards, np.float64),
            "terminations": np.asarray(self.terminations, bool),
            "truncations": np.asarray(self.truncations, bool),
            "infos": self.infos,
        }


class KeyboardSession:
    """The window, the key state and the episode loop of one recording session."""

    def __init__(self, env: gym.Env, *, episodes: int, seed: int, fps: float,
                 scale: float = 1.0) -> None:
        import pygame

        if not isinstance(env.action_space, gym.spaces.Discrete) or \
                int(env.action_space.n) != N_PAPER_ACTIONS:
            raise ValueError(
                f"keyboard recording maps keys to the {N_PAPER_ACTIONS} paper actions; this env "
                f"has {env.action_space}")
        self.pygame = pygame
        self.env, self.target, self.seed, self.fps, self.scale = env, episodes, seed, fps, scale
        self.held: set[str] = set()  # driving keys down now
        self.tapped: set[str] = set()  # driving keys pressed since the last step
        self.paused = False
        self.attempt = 0  # episode k is reset with seed + k (discarded attempts use up seeds)
        self.result = Recording()
        self.last_action = keys_to_action(set())
        pygame.display.init()
        pygame.font.init()
        self.font = pygame.font.Font(None, 22)
        self.clock = pygame.time.Clock()
        self.screen = None
        self.episode = self._start()

    def _start(self) -> _Episode:
        seed = self.seed + self.attempt
        self.attempt += 1
        obs, info = self.env.reset(seed=seed)
        return _Episode(seed, obs, info)

    def _handle_events(self) -> str | None:
        """Drain pygame's queue; returns "quit" / "discard" when asked, toggles pause itself."""
        pygame = self.pygame
        command = None
        for event in pygame.event.get():
            if event.type == pygame.QUIT:
                return "quit"
            if event.type not in (pygame.KEYDOWN, pygame.KEYUP):
                continue
            name = pygame.key.name(event.key)
            if event.type == pygame.KEYUP:
                self.held.discard(name)
                continue
            action = control_command(name)
            if action == "quit":
                return "quit"
            if action == "pause":
                self.paused = not self.paused
            elif action == "discard":
                command = "discard"
            elif name in DRIVING_KEYS:
                self.held.add(name)
                self.tapped.add(name)
        return command

    def _step(self) -> None:
        action = keys_to_action(self.held | self.tapped)
        self.tapped.clear()
        self.last_action = action
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.episode.add(action, obs, reward, terminated, truncated, info)
        if terminated or truncated:
            self.result.episodes.append(self.episode.as_dict())
            self.result.seeds.append(self.episode.seed)
            if len(self.result.episodes) < self.target:
                self.episode = self._start()

    def _status_lines(self) -> list[tuple[str, tuple[int, int, int]]]:
        """Episode / step / lane status, the current action, and the key help."""
        info = self.episode.infos[-1]
        status = (f"episode {len(self.result.episodes) + 1}/{self.target}"
                  f" (discarded {self.result.discarded})   step {len(self.episode.actions)}")
        if info.get("lane_index") is not None:
            # Lane 0 is the top lane of the picture; the target lane is drawn blue.
            status += f"   lane {info['lane_index']} -> target lane {info.get('target_lane')} (blue)"
            status += "  ON TARGET" if info.get("on_target_lane") else ""
        action = f"action: {action_label(self.last_action)}" + ("   PAUSED (P)" if self.paused else "")
        return [(status, (240, 240, 240)), (action, (240, 240, 120)), (HELP_TEXT, (170, 170, 170))]

    def _draw(self) -> None:
        pygame = self.pygame
        frame = self.env.render()
        if frame is None:
            raise RuntimeError("the env returned no frame: it must support render_mode='rgb_array'")
        surface = pygame.surfarray.make_surface(np.ascontiguousarray(np.swapaxes(frame[..., :3], 0, 1)))
        if self.scale != 1.0:
            size = (round(surface.get_width() * self.scale), round(surface.get_height() * self.scale))
            surface = pygame.transform.smoothscale(surface, size)
        lines = self._status_lines()
        bar = 6 + 21 * len(lines)
        if self.screen is None:
            width = max(surface.get_width(), self.font.size(HELP_TEXT)[0] + 12)
            self.screen = pygame.display.set_mode((width, surface.get_height() + bar))
            pygame.display.set_caption("laneshift: record demonstrations")
        self.screen.fill((20, 20, 20))
        self.screen.blit(surface, (0, bar))
        for row, (text, colour) in enumerate(lines):
            self.screen.blit(self.font.render(text, True, colour), (6, 5 + 21 * row))
        pygame.display.flip()

    def run(self, before_frame: Callable[[int], None] | None = None) -> Recording:
        """Loop until ``episodes`` are completed or the person quits."""
        frame = 0
        try:
            self._draw()
            while len(self.result.episodes) < self.target:
                if before_frame is not None:
                    before_frame(frame)
                frame += 1
                command = self._handle_events()
                if command == "quit":
                    self.result.quit_early = True
                    break
                if command == "discard":
                    self.result.discarded += 1
                    self.held.clear()
                    self.tapped.clear()
                    self.episode = self._start()
                elif not self.paused:
                    self._step()
                self._draw()
                if self.fps > 0:
                    self.clock.tick(self.fps)
        finally:
            self.pygame.display.quit()  # closes the window; env renderers need no display
        return self.result


def record_shard(
    out_dir: str | os.PathLike,
    *,
    env_id_or_scenario: str,
    env_kwargs: dict,
    episodes: int,
    seed: int = 0,
    fps: float | None = None,
    scale: float = 1.0,
    before_frame: Callable[[int], None] | None = None,
) -> Path | None:
    """Record up to ``episodes`` keyboard-driven episodes and write them at ``out_dir``.

    Returns the shard path, or None when the person quit before completing any episode
    (nothing is written then). ``fps`` <= 0 steps as fast as frames are drawn (tests).
    Ctrl-C counts as quitting; if anything else fails mid-session the completed episodes are
    still written (metadata ``aborted_by``) before the error propagates.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, not {episodes}")
    check_out_dir(out_dir)  # before anyone drives
    env_id = resolve_env_id(env_id_or_scenario)
    env = make_env(env_id, env_kwargs, render_mode="rgb_array")
    try:
        rate = float(env.metadata.get("render_fps", 10) if fps is None else fps)
        session = KeyboardSession(env, episodes=episodes, seed=seed, fps=rate, scale=scale)

        def save(recording: Recording, **extra: Any) -> Path:
            return write_shard(
                out_dir, recording.episodes, env_id=env_id, env_kwargs=env_kwargs,
                recorded_by="human", seeds=recording.seeds, env=env,
                extra_metadata={"recorder": "keyboard", "fps": rate,
                                "discarded_episodes": recording.discarded,
                                "quit_early": recording.quit_early, **extra},
            )

        try:
            recording = session.run(before_frame)
        except KeyboardInterrupt:  # Ctrl-C in the terminal counts as quitting
            recording = session.result
            recording.quit_early = True
        except Exception as exc:
            if session.result.episodes:  # never lose completed human episodes to a crash
                session.result.quit_early = True
                saved = save(session.result, aborted_by=f"{type(exc).__name__}: {exc}")
                exc.add_note(f"the {len(session.result.episodes)} completed episodes were "
                             f"saved to {saved}")
            raise
        if not recording.episodes:
            return None
        return save(recording)
    finally:
        env.close()
