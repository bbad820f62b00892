"""Keyboard -> paper action mapping for recording human demonstrations (pure, no pygame).

Arrow keys held at the moment of a step choose one of the paper's 9 actions:
up / down = speed +/- (accelerate / decelerate), left / right = curvature left / right, no key =
keep speed and heading. Keys combine (up + left = accelerate while turning left); opposite keys
cancel each other (up + down = keep speed). Control keys: P pauses / resumes, Backspace
discards the current episode, Esc or Q quits (completed episodes are saved).

Key names are pygame's ``pygame.key.name`` strings, so this module needs no display.

Example::

    >>> keys_to_action({"up", "left"}) == paper_action_index(speed=+1, turn=+1)
    True
    >>> keys_to_action(set())
    0
    >>> control_command("escape")
    'quit'

Room: the tools (demo tools). May import: anything in laneshift.
"""

from __future__ import annotations

from collections.abc import Collection

from laneshift.actors.envs.actions import paper_action_index

SPEED_UP, SPEED_DOWN, TURN_LEFT, TURN_RIGHT = "up", "down", "left", "right"
DRIVING_KEYS = frozenset({SPEED_UP, SPEED_DOWN, TURN_LEFT, TURN_RIGHT})
CONTROL_KEYS = {"p": "pause", "backspace": "discard", "escape": "quit", "q": "quit"}
N_PAPER_ACTIONS = 9


def keys_to_action(pressed: Collection[str]) -> int:
    """The paper action index for the set of held key names (other keys are ignored)."""
    speed = int(SPEED_UP in pressed) - int(SPEED_DOWN in pressed)
    turn = int(TURN_LEFT in pressed) - int(TURN_RIGHT in pressed)  # +1 = left, as in the paper
    return paper_action_index(speed=speed, turn=turn)


def control_command(key_name: str) -> str | None:
    """``"pause"``, ``"discard"``, ``"quit"`` for a control key's name, else None."""
    return CONTROL_KEYS.get(key_name)


def action_label(action: int) -> str:
    """Short text for a paper action index, e.g. ``"accelerate + left"`` (for the HUD)."""
    for speed in (0, 1, -1):
        for turn in (0, 1, -1):
            if paper_action_index(speed=speed, turn=turn) == action:
                speed_text = {0: "keep speed", 1: "accelerate", -1: "decelerate"}[speed]
                turn_text = {0: "", 1: " + left", -1: " + right"}[turn]
                return speed_text + turn_text
    raise ValueError(f"{action} is not a paper action index (0..{N_PAPER_ACTIONS - 1})")
