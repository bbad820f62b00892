"""learner.frozen_steps and learner.frozen_layers: the first N env steps of phase 2 train only part of
a frame network (linear probing, then fine-tuning). Frozen, the chosen layers (every layer but the Q
output layer, or the convolutions) keep their weights while the rest learn; thawed, they learn again;
the loop freezes them from phase 2's first update (after a pre-training that trained them) until the
run's env steps reach N, a restored learner included; a vector network or a negative count is refused
with the option's name.

In process, no Ray, no zenoh: DoubleDQN on random frames, and a Learner over fake links that hand
out random frame batches and report the env steps.
Room: tests, unit. May import: laneshift (any floor), pytest, numpy, torch, the standard library, tests/fakelinks.py."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

from laneshift import wire
from laneshift.config import ConfigError, LearnerConfig, load_run_config
from laneshift.envspec import EnvSpec
from laneshift.learner.dqn import DoubleDQN
from laneshift.learner.loop import Learner

# tests/ is not a package and pytest runs with --import-mode=importlib: load the helper by path.
_spec = importlib.util.spec_from_file_location("laneshift_tests_fakelinks", Path(__file__).with_name("fakelinks.py"))
fakelinks = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = fakelinks
_spec.loader.exec_module(fakelinks)

torch.set_num_threads(1)
FRAMES, ACTIONS = (4, 40, 40), 3


def _batch(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {"obs": rng.integers(0, 256, (n, *FRAMES), dtype=np.uint8), "action": rng.integers(0, ACTIONS, n),
            "reward": rng.standard_normal(n).astype(np.float32),
            "next_obs": rng.integers(0, 256, (n, *FRAMES), dtype=np.uint8), "terminated": np.zeros(n, np.uint8),
            "steps": np.ones(n, np.uint8), "weight": np.ones(n, np.float32), "is_demo": np.ones(n, np.uint8)}


def _copy(module: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def _same(module: torch.nn.Module, before: list[torch.Tensor]) -> bool:
    return all(torch.equal(p, b) for p, b in zip(module.parameters(), before))


@pytest.mark.parametrize("layers", ["all-but-output", "convolutions"])
@pytest.mark.parametrize("dueling", [True, False])
def test_frozen_layers_keep_their_weights_while_the_rest_learn_then_thaw(layers, dueling):
    rng = np.random.default_rng(0)
    agent = DoubleDQN(FRAMES, ACTIONS, LearnerConfig(cnn="small", batch_size=8, lr=1e-3, bc_loss_weight=1.0,
                                                     weight_decay=1e-3, dueling=dueling, frozen_layers=layers,
                                                     seed=1))
    net = agent.online
    output = net.head[-1]
    frozen = [net.features] if layers == "convolutions" else [net.features, net.head[0]]
    learning = [output] if layers == "all-but-output" else [net.head]
    agent.set_frozen(True)
    assert agent.frozen and not any(p.requires_grad for m in frozen for p in m.parameters())
    assert all(p.requires_grad for m in learning for p in m.parameters())
    before_frozen, before_learning = [_copy(m) for m in frozen], [_copy(m) for m in learning]
    for _ in range(3):
        metrics = agent.update(_batch(8, rng))
    assert np.isfinite(metrics["loss"]) and metrics["grad_norm"] > 0
    # Neither Adam nor the weight decay moved the frozen layers; the others learned.
    assert all(_same(m, b) for m, b in zip(frozen, before_frozen))
    assert all(p.grad is None for m in frozen for p in m.parameters())
    assert not any(_same(m, b) for m, b in zip(learning, before_learning))
    agent.set_frozen(False)
    assert not agent.frozen and all(p.requires_grad for p in net.parameters())
    agent.update(_batch(8, rng))
    assert not any(_same(m, b) for m, b in zip(frozen, before_frozen))
    # The target network's parameters never take gradients, frozen or not.
    assert not any(p.requires_grad for p in agent.target.parameters())


@pytest.mark.parametrize("dueling", [True, False])
def test_frozen_all_but_output_shares_one_trunk_pass_and_learns_what_the_general_path_learns(dueling):
    """Frozen all-but-output: the target's trunk equals the online one's, so next_obs' features serve
    both output layers (2 trunk passes of the batch, not 3); the losses and the output layer's weights
    after a few updates match the general path's to float rounding, target syncs included."""
    cfg = LearnerConfig(cnn="small", batch_size=8, lr=1e-3, bc_loss_weight=1.0, dueling=dueling, seed=1,
                        augment="shift", target_update_period=2)
    shared, general = DoubleDQN(FRAMES, ACTIONS, cfg), DoubleDQN(FRAMES, ACTIONS, cfg)
    general.load_state_dict(shared.state_dict())
    for agent in (shared, general):
        agent.set_frozen(True)
    assert shared.shared_trunk
    rng_a, rng_b = np.random.default_rng(0), np.random.default_rng(0)
    for _ in range(5):
        general.shared_trunk = False  # the path every other configuration takes (a sync re-checks it)
        a, b = shared.update(_batch(8, rng_a)), general.update(_batch(8, rng_b))
        assert shared.shared_trunk
        assert a["loss"] == pytest.approx(b["loss"], rel=1e-5, abs=1e-6)
    for p, q in zip(shared.online.head[-1].parameters(), general.online.head[-1].parameters()):
        torch.testing.assert_close(p, q, rtol=1e-5, atol=1e-6)
    shared.set_frozen(False)
    assert not shared.shared_trunk


def test_the_trunk_is_shared_only_once_the_target_holds_the_online_trunk():
    cfg = LearnerConfig(cnn="small", batch_size=8, lr=1e-3, seed=1, target_update_period=3)
    agent, rng = DoubleDQN(FRAMES, ACTIONS, cfg), np.random.default_rng(0)
    agent.update(_batch(8, rng))  # the online trunk moves, the target's stays: they differ now
    agent.set_frozen(True)
    assert not agent.shared_trunk
    agent.update(_batch(8, rng))
    assert not agent.shared_trunk
    agent.update(_batch(8, rng))  # the third update syncs the target: from here on the trunks are equal
    assert agent.shared_trunk
    conv = DoubleDQN(FRAMES, ACTIONS, dataclasses.replace(cfg, frozen_layers="convolutions"))
    conv.set_frozen(True)
    assert not conv.shared_trunk  # the hidden layer still learns: its trunk is not the target's
    vanilla = DoubleDQN(FRAMES, ACTIONS, dataclasses.replace(cfg, double=False))
    vanilla.set_frozen(True)
    assert not vanilla.shared_trunk


def test_a_vector_network_or_a_bad_count_is_refused_with_the_options_name():
    agent = DoubleDQN((4,), ACTIONS, LearnerConfig(hidden=(8,)))
    with pytest.raises(ValueError, match="learner.frozen_steps"):
        agent.set_frozen(True)
    with pytest.raises(ConfigError, match="learner.frozen_steps"):
        LearnerConfig(frozen_steps=-1)
    with pytest.raises(ConfigError, match="learner.frozen_layers"):
        LearnerConfig(frozen_layers="head")
    with pytest.raises(ConfigError, match="learner.frozen_steps.*grayscale"):
        load_run_config(overrides={"learner.frozen_steps": 1000})
    cfg = load_run_config(overrides={"learner.frozen_steps": 1000, "env.observation": "grayscale",
                                     "learner.cnn": "small"})
    assert cfg.learner.frozen_steps == 1000 and cfg.learner.frozen_layers == "all-but-output"


class FrameLinks(fakelinks.QuietLinks):
    """LearnerLinks whose replay server hands out random demo frame batches and reports ``env_steps``."""

    def __init__(self) -> None:
        super().__init__()
        self.env_steps, self.rng = 0, np.random.default_rng(3)

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch:
        n = req.batch_size * req.num_batches
        b = _batch(n, self.rng)
        return wire.SampledBatch(obs=b["obs"], action=b["action"], reward=b["reward"], next_obs=b["next_obs"],
                                 terminated=b["terminated"], steps=b["steps"], is_demo=b["is_demo"],
                                 index=np.arange(n), weight=b["weight"], num_batches=req.num_batches, info={})

    def replay_stats(self) -> dict:
        return {"tables": {"online": {"size": 100, "capacity": 1000}}, "actors": {},
                "actors_total": {"env_steps": self.env_steps, "lost_items": 0},
                "rates": {"inserts_per_s": 10.0, "samples_per_s": 80.0}, "demo_share_buffer": 1.0,
                "demo_share_recent_samples": 1.0, "sampled_rows": 0}


def _learner(run_dir, links: FrameLinks, **overrides) -> Learner:
    cfg = load_run_config(overrides={
        "env.observation": "grayscale", "learner.cnn": "small", "learner.batch_size": 4, "learner.prefetch": 2,
        "learner.publish_every": 2, "learner.device": "cpu", "learner.checkpoint_every_s": 0,
        "learner.bc_loss_weight": 1.0, "replay.demo_mode": "dqfd", "learner.phase1_updates": 4,
        "learner.frozen_steps": 300, "train.run_dir": str(run_dir), **overrides})
    spec = EnvSpec("fake-frames", wire.TransitionSchema(FRAMES, "|u1", ACTIONS), ())
    return Learner(cfg, spec, links, threading.Event())


def test_the_loop_trains_the_convolutions_in_phase1_freezes_them_in_phase2_until_the_env_steps_reach_n(tmp_path):
    links = FrameLinks()
    learner = _learner(tmp_path, links)
    features = learner.agent.online.features  # frozen by the default learner.frozen_layers (all-but-output)
    start = _copy(features)
    learner._rehearsal_phase1()
    assert learner.phase == 2 and learner.agent.updates == 4
    assert not _same(features, start)  # pre-training trained the convolutions
    assert learner.agent.frozen  # frozen from phase 2's first update
    pre_trained = _copy(features)
    learner._async_step()
    assert learner.agent.updates > 4 and _same(features, pre_trained)
    links.env_steps = 299
    learner._log()
    learner._follow_schedules()
    assert learner.agent.frozen
    links.env_steps = 300
    learner._log()
    learner._follow_schedules()
    assert not learner.agent.frozen
    learner._async_step()
    assert not _same(features, pre_trained)
    learner._finish()

    # A learner restored past N starts thawed at its first schedule reading; one before N, frozen.
    again = _learner(tmp_path, FrameLinks())
    assert again.restored_from and again.phase == 2 and again.env_steps == 300
    again._follow_schedules()
    assert not again.agent.frozen
    early = _learner(tmp_path / "early", FrameLinks(), **{"replay.demo_mode": "none"})
    assert early.phase == 0 and not early.agent.frozen  # no pre-training: phase 0, the whole run
    early._follow_schedules()
    assert early.agent.frozen
    early._finish()
