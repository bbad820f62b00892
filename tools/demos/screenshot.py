"""Save a picture of the ``laneshift demos record`` window without a screen (for the docs).

Runs the recorder's own :class:`~laneshift.tools.demos.record.KeyboardSession` (same window, same
status bar) under ``SDL_VIDEODRIVER=dummy``, where pygame draws into an in-memory surface. The
keys are pressed by the scripted driver: every frame, its action is turned into the arrow keys
that give it (the inverse of :func:`laneshift.tools.demos.keys.keys_to_action`) and posted as real
pygame key events, so the picture shows what a person driving well would see. At frame
``frame`` the window surface is saved with ``pygame.image.save`` and Esc is posted; nothing is
recorded or written besides the picture.

Imports: pygame (through ``.record``), the demos package, laneshift's scripted driver (lazily).

Example::

    SDL_VIDEODRIVER=dummy python -m laneshift.tools.demos.screenshot docs/img/demos-record-window.png

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from laneshift.demos.envsupport import make_env, resolve_env_id
from .keys import DRIVING_KEYS, SPEED_DOWN, SPEED_UP, TURN_LEFT, TURN_RIGHT, keys_to_action


def action_keys(action: int) -> frozenset[str]:
    """The arrow keys whose combination gives paper action ``action`` (none for "keep")."""
    for up_down in (set(), {SPEED_UP}, {SPEED_DOWN}):
        for left_right in (set(), {TURN_LEFT}, {TURN_RIGHT}):
            keys = frozenset(up_down | left_right)
            if keys_to_action(keys) == action:
                return keys
    raise ValueError(f"{action} is not a paper action index")


def save_record_window(png: str | os.PathLike, *, scenario: str = "straight",
                       env_kwargs: dict | None = None, seed: int = 0, frame: int = 40,
                       scale: float = 1.0, episodes: int = 20) -> Path:
    """Drive ``frame`` frames of the recorder with the scripted driver's keys and save the
    window at that frame to ``png``. ``episodes`` is only what the status bar counts towards."""
    # The dummy driver unless the caller chose one: the picture needs no screen.
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    import pygame

    from .drivers import scripted_driver
    from .record import KeyboardSession

    png = Path(png)
    env = make_env(resolve_env_id(scenario), dict(env_kwargs or {}), render_mode="rgb_array")
    try:
        session = KeyboardSession(env, episodes=episodes, seed=seed, fps=0, scale=scale)
        driver = scripted_driver(env)
        saved: list[Path] = []

        def before_frame(index: int) -> None:
            if index == frame:  # the window now shows the state after frame - 1 steps
                png.parent.mkdir(parents=True, exist_ok=True)
                pygame.image.save(session.screen, str(png))
                saved.append(png)
                pygame.event.post(pygame.event.Event(pygame.KEYDOWN, key=pygame.K_ESCAPE))
                return
            wanted = action_keys(int(driver(None)))
            for name in sorted(DRIVING_KEYS):  # release the others, press the wanted ones
                kind = pygame.KEYDOWN if name in wanted else pygame.KEYUP
                pygame.event.post(pygame.event.Event(kind, key=pygame.key.key_code(name)))

        session.run(before_frame)
    finally:
        env.close()
    if not saved:
        raise RuntimeError(f"the episode ended before frame {frame}: nothing saved")
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m laneshift.tools.demos.screenshot",
                                     description="Save a picture of the recording window.")
    parser.add_argument("png", help="where to write the PNG")
    parser.add_argument("--scenario", default="straight")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frame", type=int, default=40, help="frame to save (default 40)")
    parser.add_argument("--scale", type=float, default=1.0)
    args = parser.parse_args(argv)
    path = save_record_window(args.png, scenario=args.scenario, seed=args.seed, frame=args.frame,
                              scale=args.scale)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
