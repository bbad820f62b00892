"""The recorder's keyboard -> paper action mapping (pure functions, no display needed).

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import itertools

import pytest

from laneshift.actors.envs.actions import PAPER_ACTIONS
from laneshift.tools.demos.keys import action_label, control_command, keys_to_action


def test_single_keys_and_no_key() -> None:
    assert PAPER_ACTIONS[keys_to_action(set())] == (0.0, 0.0)
    assert PAPER_ACTIONS[keys_to_action({"up"})] == (0.1, 0.0)
    assert PAPER_ACTIONS[keys_to_action({"down"})] == (-0.1, 0.0)
    assert PAPER_ACTIONS[keys_to_action({"left"})] == (0.0, 0.01)  # +kappa = left in the paper
    assert PAPER_ACTIONS[keys_to_action({"right"})] == (0.0, -0.01)


def test_combinations_cover_all_nine_actions() -> None:
    seen = {}
    for speed_key, turn_key in itertools.product((None, "up", "down"), (None, "left", "right")):
        pressed = {k for k in (speed_key, turn_key) if k}
        seen[keys_to_action(pressed)] = pressed
    assert sorted(seen) == list(range(9))
    assert PAPER_ACTIONS[keys_to_action({"up", "left"})] == (0.1, 0.01)
    assert PAPER_ACTIONS[keys_to_action({"down", "right"})] == (-0.1, -0.01)


def test_opposite_keys_cancel_and_others_are_ignored() -> None:
    assert keys_to_action({"up", "down"}) == keys_to_action(set())
    assert keys_to_action({"left", "right", "up"}) == keys_to_action({"up"})
    assert keys_to_action({"space", "a", "left"}) == keys_to_action({"left"})


def test_control_keys() -> None:
    assert control_command("p") == "pause"
    assert control_command("backspace") == "discard"
    assert control_command("escape") == control_command("q") == "quit"
    assert control_command("up") is None


def test_labels() -> None:
    assert action_label(keys_to_action({"up", "right"})) == "accelerate + right"
    assert action_label(keys_to_action(set())) == "keep speed"
    with pytest.raises(ValueError):
        action_label(9)
