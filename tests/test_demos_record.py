"""Keyboard recording driven by injected pygame key events (SDL_VIDEODRIVER=offscreen).

The scripted events go through pygame's real event queue; the test checks that every stored
transition carries the action of the keys pressed, that pause / discard / quit behave, and that
the stored transitions are what the env does with those actions.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from laneshift.demos import load_shard
from laneshift.tools.demos.keys import keys_to_action

ENV_KWARGS = {"observation": "vector", "max_steps": 4}


def _key(kind: str, name: str):
    import pygame

    event_type = pygame.KEYDOWN if kind == "down" else pygame.KEYUP
    return pygame.event.Event(event_type, key=pygame.key.key_code(name))


# frame -> events posted before the recorder reads the queue for that frame
SCRIPT = {
    # episode A (seed 0): up, up+left, left, tap down
    0: [("down", "up")],
    1: [("down", "left")],
    2: [("up", "up")],
    3: [("up", "left"), ("down", "down"), ("up", "down")],
    # episode B (seed 1): pause, press right while paused, resume -> one step, then discard
    4: [("down", "p")],
    5: [("down", "right")],
    6: [("down", "p")],
    7: [("up", "right"), ("down", "backspace")],
    # episode C (seed 2): nothing, up+down (cancel), tap right, left
    8: [],
    9: [("down", "up"), ("down", "down")],
    10: [("up", "up"), ("up", "down"), ("down", "right"), ("up", "right")],
    11: [("down", "left")],
    # episode D (seed 3) is quit before its first step: not stored
    12: [("down", "escape")],
}
KEEP = keys_to_action(set())
EXPECTED = {
    0: [keys_to_action({"up"}), keys_to_action({"up", "left"}), keys_to_action({"left"}),
        keys_to_action({"down"})],
    2: [KEEP, KEEP, keys_to_action({"right"}), keys_to_action({"left"})],
}


@pytest.fixture()
def offscreen(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "offscreen")  # a real (in-memory) window, no screen


def test_record_round_trip_with_scripted_keys(offscreen, tmp_path: Path) -> None:
    import pygame

    from laneshift.tools.demos.record import record_shard

    screens = []

    def before_frame(frame: int) -> None:
        if frame == 1:  # the window shows the scene, not a black frame
            screens.append(pygame.surfarray.array3d(pygame.display.get_surface()))
        for kind, name in SCRIPT.get(frame, []):
            pygame.event.post(_key(kind, name))

    path = record_shard(tmp_path / "human", env_id_or_scenario="straight", env_kwargs=ENV_KWARGS,
                        episodes=3, seed=0, fps=0, before_frame=before_frame)
    shard = load_shard(path, env_id="straight", n_actions=9)
    meta = shard.metadata
    assert meta["recorded_by"] == "human" and meta["seeds"] == [0, 2]
    assert meta["episodes"] == 2 and meta["discarded_episodes"] == 1 and meta["quit_early"]
    assert shard.actions.tolist() == EXPECTED[0] + EXPECTED[2]
    assert shard.episode_ids.tolist() == [0] * 4 + [1] * 4
    assert shard.truncations.tolist() == [False, False, False, True] * 2
    assert meta["survival_rate"] == 1.0 and meta["achievement_rate"] is not None
    assert screens and screens[0].std() > 10

    # the stored transitions are what the env does with the chosen actions
    from laneshift.actors.envs import make_env

    env = make_env("straight", **ENV_KWARGS)
    for episode, seed in enumerate(meta["seeds"]):
        obs, _ = env.reset(seed=seed)
        rows = np.flatnonzero(shard.episode_ids == episode)
        for row in rows:
            np.testing.assert_array_equal(shard.observations[row], obs)
            obs, reward, *_ = env.step(int(shard.actions[row]))
            np.testing.assert_array_equal(shard.next_observations[row], obs)
            assert shard.rewards[row] == np.float32(reward)


def test_quit_before_any_episode_writes_nothing(offscreen, tmp_path: Path) -> None:
    import pygame

    from laneshift.tools.demos.record import record_shard

    def before_frame(frame: int) -> None:
        pygame.event.post(_key("down", "up") if frame == 0 else _key("down", "q"))

    out = tmp_path / "none"
    assert record_shard(out, env_id_or_scenario="straight", env_kwargs=ENV_KWARGS, episodes=2,
                        seed=0, fps=0, before_frame=before_frame) is None
    assert not out.exists()


def test_record_refuses_non_paper_action_envs(offscreen, tmp_path: Path) -> None:
    from laneshift.tools.demos.record import record_shard

    with pytest.raises(ValueError, match="9 paper actions"):
        record_shard(tmp_path / "lka", env_id_or_scenario="straight",
                     env_kwargs={"action_set": "meta"}, episodes=1, fps=0)


def test_completed_episodes_survive_a_crash(offscreen, tmp_path: Path) -> None:
    from laneshift.tools.demos.record import record_shard

    def before_frame(frame: int) -> None:
        if frame == 6:  # after one 4-step episode and two steps of the next
            raise RuntimeError("display lost")

    with pytest.raises(RuntimeError, match="display lost") as info:
        record_shard(tmp_path / "h", env_id_or_scenario="straight", env_kwargs=ENV_KWARGS,
                     episodes=3, seed=0, fps=0, before_frame=before_frame)
    assert "1 completed episodes were saved" in "".join(info.value.__notes__)
    shard = load_shard(tmp_path / "h")
    assert shard.metadata["episodes"] == 1 and shard.metadata["aborted_by"].endswith("display lost")
    assert shard.actions.tolist() == [KEEP] * 4
