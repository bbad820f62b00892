"""`laneshift eval` reads what it can from the checkpoint (observation type, scenario, shield), and
`--video` records the evaluation's own first episodes as a GIF: on tiny hand-made checkpoints and
5-step episodes, seconds in all.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, Pillow, the standard library
and what the code under test needs."""

from __future__ import annotations

import json

import pytest

from laneshift.tools.cli import main

STRAIGHT = "laneshift/StraightLaneChange-v0"


def _checkpoint(path, obs_shape: tuple[int, ...], env_id: str = STRAIGHT, **meta):
    """A random network of the checkpoint format, with the learner's metadata."""
    import torch

    from laneshift.qnet import build_q_network, save_checkpoint

    torch.manual_seed(0)
    cnn = meta.pop("cnn", "small")
    net = build_q_network(obs_shape, 9, (8,), cnn=cnn)
    dtype = "|u1" if len(obs_shape) == 3 else "<f4"
    return save_checkpoint(net, path, {"env_id": env_id, "obs_shape": ",".join(map(str, obs_shape)),
                                       "obs_dtype": dtype, "n_actions": 9, "hidden": "8", "dueling": 0,
                                       "cnn": cnn, **meta})


def _vector_shape(scenario: str = "straight") -> tuple[int, ...]:
    from laneshift.actors.envs import spec_of
    from laneshift.config import EnvConfig

    return tuple(spec_of(EnvConfig(scenario=scenario)).schema.obs_shape)


def test_a_pixel_checkpoint_is_evaluated_on_frames_without_observation_flag(tmp_path, capsys):
    path = _checkpoint(tmp_path / "pixels.safetensors", (4, 100, 100))
    assert main(["eval", "--checkpoint", str(path), "--episodes", "1", "--max-steps", "3", "--json"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["episodes"] == 1
    assert "from the checkpoint: observation grayscale" in out.err


def test_an_explicit_observation_that_contradicts_the_checkpoint_is_refused_in_one_line(tmp_path, capsys):
    path = _checkpoint(tmp_path / "pixels.safetensors", (4, 100, 100))
    for choice in (["--observation", "vector"], ["--set", "env.observation=vector"]):
        assert main(["eval", "--checkpoint", str(path), "--episodes", "1", "--max-steps", "3", *choice]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("laneshift eval: "), err
        assert "(4, 100, 100)" in err[0] and "env.observation=grayscale" in err[0]


def test_the_checkpoints_env_id_chooses_the_scenario_unless_scenario_is_given(tmp_path, capsys):
    shape = _vector_shape("merge")
    path = _checkpoint(tmp_path / "merge.safetensors", shape, env_id="laneshift/MergeLaneChange-v0")
    assert main(["eval", "--checkpoint", str(path), "--episodes", "1", "--max-steps", "3"]) == 0
    assert "from the checkpoint: scenario merge" in capsys.readouterr().err
    if shape == _vector_shape("straight"):  # the same layout on both roads: --scenario wins, quietly
        assert main(["eval", "--checkpoint", str(path), "--scenario", "straight", "--episodes", "1",
                     "--max-steps", "3"]) == 0
        assert "from the checkpoint" not in capsys.readouterr().err


def test_a_shield_checkpoint_takes_other_shield_figures_without_restating_the_shield(tmp_path, capsys):
    path = _checkpoint(tmp_path / "shield.safetensors", _vector_shape(), shield=1, shield_gap=2.5)
    assert main(["eval", "--checkpoint", str(path), "--episodes", "1", "--max-steps", "3", "--json"]) == 0
    out = capsys.readouterr()
    assert "from the checkpoint: shield True, shield_gap 2.5" in out.err
    assert "shielded_step_rate" in json.loads(out.out)
    assert main(["eval", "--checkpoint", str(path), "--episodes", "1", "--max-steps", "3",
                 "--set", "env.shield_decel=1.0"]) == 0
    assert "shield True, shield_gap 2.5" in capsys.readouterr().err
    # Without a checkpoint that says so, the figures alone are refused in one line.
    plain = _checkpoint(tmp_path / "plain.safetensors", _vector_shape())
    assert main(["eval", "--checkpoint", str(plain), "--episodes", "1", "--set", "env.shield_gap=2"]) != 0
    assert "needs env.shield=true" in capsys.readouterr().err


@pytest.mark.parametrize("fps, every", [(None, 1), (5.0, 2)])
def test_video_writes_the_evaluated_episodes_frames(tmp_path, capsys, fps, every):
    from PIL import Image

    path = _checkpoint(tmp_path / "vector.safetensors", _vector_shape())
    argv = ["eval", "--checkpoint", str(path), "--episodes", "2", "--max-steps", "5", "--seed", "7", "--json"]
    assert main(argv) == 0
    plain = json.loads(capsys.readouterr().out)
    gif = tmp_path / "out" / "x.gif"
    assert main([*argv, "--video", str(gif), *([] if fps is None else ["--video-fps", str(fps)])]) == 0
    recorded = json.loads(capsys.readouterr().out)
    video = recorded.pop("video")
    assert recorded == plain  # the same episodes, the same numbers: drawing changes nothing
    (episode,) = video["episodes"]  # --video-episodes 1: the first of the two
    steps = episode["steps"]
    assert episode["seed"] == 7 and 1 <= steps <= 5
    # The start and each step's outcome, every k-th of them, the last always kept.
    expected = len(range(0, steps + 1, every)) + (steps % every != 0)
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.n_frames == expected == video["frames"] == episode["frames"]
        assert im.size == (600, 300) and im.info["duration"] == 100 * every
        im.seek(im.n_frames // 2)
        assert len(im.convert("RGB").getcolors(maxcolors=256) or ()) >= 4  # a real picture, not a blank one


def test_video_refuses_what_it_cannot_write(tmp_path, capsys):
    path = _checkpoint(tmp_path / "vector.safetensors", _vector_shape())
    with pytest.raises(SystemExit) as stop:  # refused while parsing, before any work
        main(["eval", "--checkpoint", str(path), "--video", str(tmp_path / "x.mp4")])
    assert stop.value.code == 2 and "no MP4 writer" in capsys.readouterr().err
    lka = _checkpoint(tmp_path / "lka.safetensors", _vector_shape("lka"), env_id="laneshift/LaneKeepingAssist-v0")
    assert main(["eval", "--checkpoint", str(lka), "--episodes", "1", "--video", str(tmp_path / "l.gif")]) == 2
    assert capsys.readouterr().err.strip() == "laneshift eval: --video: the lka env draws no top-down view to record"
    assert not (tmp_path / "l.gif").exists()
