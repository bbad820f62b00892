"""Evaluation: Wilson intervals, rates, and the MATLAB LKA response test.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift.config import EnvConfig
from laneshift.tools.studies.evaluate import evaluate_policy, lka_response, plot_lka_response, wilson_ci95


def test_wilson_interval_known_values():
    lo, hi = wilson_ci95(50, 100)
    assert (round(lo, 4), round(hi, 4)) == (0.4038, 0.5962)
    assert wilson_ci95(0, 10)[0] == 0.0 and wilson_ci95(10, 10)[1] == 1.0


def test_lka_expert_response_meets_the_matlab_reference(tmp_path):
    from laneshift.actors.envs.demonstrator import LKAExpert

    resp = lka_response(LKAExpert)
    assert resp["e1_0"] == -0.4 and resp["trace"]["e1"][0] == pytest.approx(-0.4)
    assert not resp["left_lane"] and resp["centred_after_s"] is not None and resp["centred_after_s"] <= 2.5
    t = np.asarray(resp["trace"]["t"])
    after = np.asarray(resp["trace"]["e1"])[t >= resp["centred_after_s"]]
    assert np.abs(after).max() <= 0.05  # the definition: centred for the rest of the episode
    # The expert's steering ends alternating between neighbouring 1-degree actions: settled.
    assert resp["steering_settled_after_s"] is not None and resp["steering_settled_after_s"] <= 2.5
    assert resp["steering_chatter_deg"] <= 1.0
    png = plot_lka_response(resp, tmp_path / "resp.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_keep_lane_policy_on_straight_never_achieves_from_a_non_target_lane():
    from laneshift.actors.envs.demonstrator import KeepLaneDriver

    cfg = EnvConfig(scenario="straight", initial_lane="non-target")
    result = evaluate_policy(KeepLaneDriver, cfg, episodes=3, seed=0)
    assert result["achievement_rate"] == 0.0
    assert 0.0 <= result["achievement_ci95"][0] <= result["achievement_ci95"][1] <= 1.0


def test_a_checkpoint_of_another_observation_layout_is_refused_with_the_fix(tmp_path, capsys):
    from laneshift.tools.cli import main
    from laneshift.qnet import build_q_network
    from laneshift.qnet import save_checkpoint

    path = save_checkpoint(build_q_network((67,), 9, (8,)), tmp_path / "old.safetensors",
                           {"obs_shape": "67", "hidden": "8", "n_actions": 9})
    assert main(["eval", "--checkpoint", str(path), "--scenario", "straight", "--episodes", "1"]) == 2
    assert "env.lane_features=false" in capsys.readouterr().err
    assert main(["eval", "--checkpoint", str(path), "--scenario", "straight", "--episodes", "1", "--max-steps", "5",
                 "--set", "env.lane_features=false"]) == 0


def test_crashes_are_counted_by_kind_and_starting_lane():
    from laneshift.config import EnvConfig
    from laneshift.tools.studies.evaluate import evaluate_policy

    # Always turning left leaves the road or hits someone: every episode crashes, each counted once.
    r = evaluate_policy(lambda env: (lambda obs: 1), EnvConfig(scenario="straight", max_steps=200), 6, seed=3)
    counted = sum(n for by_lane in r["crashes"].values() for n in by_lane.values())
    assert counted == round((1 - r["survival_rate"]) * 6) and set(r["crashes"]) <= {"collision", "offroad"}
    assert "offroad" in r["crashes"]


def test_demo_agreement_counts_the_states_where_the_greedy_action_is_the_demonstrators(tmp_path):
    import numpy as np
    import torch

    from laneshift.tools.demos.generate import generate_shard
    from laneshift.demos.shard import load_shard
    from laneshift.tools.studies.evaluate import demo_agreement
    from laneshift.qnet import build_q_network
    from laneshift.qnet import save_checkpoint

    shard_dir = generate_shard(tmp_path / "demos", env_id_or_scenario="straight", env_kwargs={"max_steps": 30},
                               episodes=2, seed=0)
    shard = load_shard(shard_dir)
    net = build_q_network((82,), 9, (8,))
    for p in net.parameters():
        torch.nn.init.zeros_(p)
    net.net[-1].bias.data[0] = 1.0  # always action 0 ("keep speed, keep heading")
    path = save_checkpoint(net, tmp_path / "c.safetensors", {"obs_shape": "82", "hidden": "8", "n_actions": 9})
    out = demo_agreement(path, shard_dir)
    assert out["states"] == len(shard.actions) == 60
    assert out["agreement"] == np.mean(shard.actions == 0)
    assert out["speed_agreement"] == np.mean(shard.actions // 3 == 0)


def test_the_policy_vehicles_are_driven_by_the_network_under_evaluation(tmp_path):
    """env.policy_vehicles: the paper's third kind of vehicle is a copy of the evaluated model."""
    import torch

    from laneshift.actors.envs import spec_of
    from laneshift.qnet import build_q_network, save_checkpoint
    from laneshift.tools.studies.evaluate import load_greedy_policy

    cfg = EnvConfig(scenario="straight", policy_vehicles=3, max_steps=5)
    schema = spec_of(cfg).schema
    torch.manual_seed(0)
    net = build_q_network(schema.obs_shape, schema.n_actions, (8,))
    path = save_checkpoint(net, tmp_path / "n.safetensors",
                           {"obs_shape": ",".join(map(str, schema.obs_shape)), "n_actions": schema.n_actions,
                            "hidden": "8", "dueling": 0})
    greedy = load_greedy_policy(path)
    rows_seen: list[int] = []
    batch = greedy.batch
    greedy.batch = lambda obs: (rows_seen.append(len(obs)), batch(obs))[1]
    evaluate_policy(lambda env: greedy, cfg, episodes=1, seed=3)
    assert rows_seen and max(rows_seen) > 1  # the ego's calls are one row; the traffic's are several
    assert evaluate_policy(lambda env: greedy, EnvConfig(scenario="straight", max_steps=5), 1, seed=3)["episodes"] == 1


def test_each_episodes_outcome_is_written_and_adds_up_to_the_rates(tmp_path, capsys):
    """``laneshift eval --episodes-out``: a line per episode, on the seeds the rates came from, so
    two policies (here the scripted driver and one that always turns left) compare episode by
    episode; the lines add up to the printed rates."""
    import json

    from laneshift.tools.cli import main

    out = tmp_path / "driver.jsonl"
    assert main(["eval", "--driver", "scripted", "--scenario", "straight", "--episodes", "4", "--seed", "7",
                 "--max-steps", "60", "--initial-lane", "non-target", "--episodes-out", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    driver = [json.loads(line) for line in out.read_text().splitlines()]
    assert [o["seed"] for o in driver] == [7, 8, 9, 10] and result["episodes_out"] == str(out)
    assert sum(o["survived"] for o in driver) / 4 == result["survival_rate"]
    assert sum(o["achieved"] for o in driver) / 4 == result["achievement_rate"]
    # When the lane changed: one step per change, in order, inside the episode; a car that ended in
    # another lane than it started in changed at least once.
    for o in driver:
        assert o["lane_changes"] == sorted(o["lane_changes"]) and all(0 < s <= o["steps"] for s in o["lane_changes"])
        assert (o["end_lane"] != o["start_lane"]) <= bool(o["lane_changes"])
    assert any(o["lane_changes"] for o in driver)  # the driver changes lanes from a non-target lane
    left: list[dict] = []
    r = evaluate_policy(lambda env: (lambda obs: 1), EnvConfig(scenario="straight", max_steps=200,
                                                               initial_lane="non-target"), 4, seed=7, outcomes=left)
    assert [o["start_lane"] for o in left] == [o["start_lane"] for o in driver]  # the same episodes
    assert all(not o["survived"] and not o["achieved"] and o["crash"] in ("collision", "offroad") for o in left)
    assert r["survival_rate"] == 0.0 and all(o["steps"] < 200 for o in left)
