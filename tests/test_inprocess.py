"""The component graph in one process (threads + in-memory links): fast checks of the worker and
learner logic, with every message still encoded and decoded by the wire contract.

Room: tests, unit. May import: laneshift (any floor), pytest, numpy, the standard library and what
the code under test needs."""

from __future__ import annotations

import numpy as np
import pytest

from laneshift import wire
from laneshift.actors.worker import expand_version_runs
from laneshift.config import load_run_config
from laneshift.deploy.builder import Builder
from laneshift.deploy.inprocess import Board, InProcessActorLinks, train_inprocess
from laneshift.qnet import build_q_network, to_wire

FAST = {"env.scenario": "lka", "actor.send_every": 50, "learner.hidden": "32,32", "learner.batch_size": 32,
        "learner.publish_every": 5, "replay.min_size": 100, "replay.samples_per_insert": 4,
        "replay.spi_tolerance": 512}


def test_async_inprocess_respects_the_sample_to_insert_ratio(tmp_path):
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 2000, "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    replay = result["replay"]
    assert [w["env_steps"] for w in result["workers"]] == [1000, 1000]
    assert replay["tables"]["online"]["inserted"] == 2000
    # Rows sampled stay within the ratio (4 per insert after min_size) plus the tolerance.
    assert replay["sampled_rows"] <= (2000 - 100) * 4 + 512
    # Every row sampled trained the learner, but for the requests in flight when it stopped
    # (learner/prefetch.py: at most one queued and one being asked), which it counts.
    unused = result["learner"]["sample_rows_unused"]
    assert result["updates"] * 32 + unused == replay["sampled_rows"] and unused <= 2 * 4 * 32
    assert result["version"] == result["updates"] // 5


def test_a_run_with_held_exploration_stores_every_env_step(tmp_path):
    """ez-greedy (actor.hold_mu) in a real worker: the run spends its budget and stores each step once."""
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 1000, "actor.hold_mu": 2.0, "actor.hold_max": 20,
                                     "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    assert result["replay"]["tables"]["online"]["inserted"] == 1000


def test_sync_inprocess_rounds(tmp_path):
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 1000, "train.parallel": "sync",
                                     "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    used = [expand_version_runs(w["version_runs"]) for w in result["workers"]]
    assert used[0] == used[1] == list(range(10))


def test_prioritized_replay_gets_priorities_from_the_learner(tmp_path):
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 1500, "replay.sampler": "prioritized",
                                     "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    sampler = result["replay"]["sampler"]
    assert sampler["kind"] == "prioritized"
    # One priority message per sample reply trained on, each applied (none refused); the replies
    # in flight when the learner stopped (at most 2, learner/prefetch.py) made no update.
    served = result["replay"]["requests"]["served"]
    assert 0 < served - 2 <= sampler["priority_updates"] <= served
    assert result["replay"]["rejected"] == {}
    assert sampler["max_priority"] > 0


def test_stop_return_ends_the_run_at_the_first_episode_that_reaches_it(tmp_path):
    # LKA returns are <= 0: a threshold of -1e9 is met by the very first episode.
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 100_000, "train.stop_return": -1e9,
                                     "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    reason = result["learner"]["stop_reason"]
    assert reason["criterion"] == "stop_return" and reason["episode"] == 1
    assert sum(w["env_steps"] for w in result["workers"]) < 100_000  # stopped long before the budget


def test_a_callers_stop_ends_the_run_early_with_a_final_checkpoint(tmp_path):
    """``train_inprocess(cfg, stop)``: a caller's deadline ends the workers' loops long before the
    budget, and the learner still writes its final network."""
    import threading

    stop = threading.Event()
    timer = threading.Timer(3.0, stop.set)
    timer.start()
    cfg = load_run_config(overrides={**FAST, "train.env_steps": 10_000_000, "train.run_dir": str(tmp_path)})
    try:
        result = train_inprocess(cfg, stop)
    finally:
        timer.cancel()
    steps = sum(w["env_steps"] for w in result["workers"])
    assert 0 < steps < 10_000_000
    assert result["replay"]["tables"]["online"]["inserted"] == steps
    assert list(tmp_path.glob("**/final.safetensors"))


def test_the_worker_gets_decoded_weights_and_counts_those_it_cannot_use(tmp_path):
    """The links decode each WEIGHTS message: the worker gets ``wire.Weights``, or the WireError
    of a message that cannot be read; that one and another network's weights are counted in
    ``bad_weights`` and the worker keeps acting with the weights it has."""
    cfg = load_run_config(overrides={**FAST, "actor.workers": 1, "train.run_dir": str(tmp_path)})
    builder = Builder(cfg)
    board = Board(cores=[builder.replay_core(0)])
    links, worker = InProcessActorLinks(board, "w0"), builder.env_worker(0)
    schema = builder.spec.schema
    try:
        board.weights = b"not a weights message"
        update = links.latest_weights()
        assert isinstance(update, wire.WireError) and not worker._apply(update)
        board.weights = to_wire(build_q_network(schema.obs_shape, schema.n_actions, (8,)), 1, 0, 0)
        assert not worker._apply(links.latest_weights())  # another network's shapes
        assert links.latest_weights() is None  # nothing new
        board.weights = to_wire(build_q_network(schema.obs_shape, schema.n_actions, cfg.learner.hidden), 2, 0, 5)
        update = links.latest_weights()
        assert isinstance(update, wire.Weights) and (update.version, update.updates) == (2, 5)
        assert worker._apply(update) and worker.policy.version == 2
        assert (worker.bad_weights, worker.weight_updates) == (2, 1)
    finally:
        worker.close()


class StoppedLinks(InProcessActorLinks):
    """A worker's in-memory links whose run is stopped (the launcher's graceful end: the stop
    message) the moment the worker sends batch ``at_seq``, or ends its first episode."""

    def __init__(self, board: Board, name: str, at_seq: int | None = None, at_episode: bool = False):
        super().__init__(board, name)
        self.at_seq, self.at_episode = at_seq, at_episode
        self.sent: list[wire.TransitionBatch] = []
        self.first_episode: wire.EpisodeRecord | None = None

    def send_transitions(self, batch: wire.TransitionBatch) -> None:
        super().send_transitions(batch)
        self.sent.append(batch)
        if batch.seq == self.at_seq:
            self.board.stop.set()

    def send_episode(self, record: wire.EpisodeRecord) -> None:
        super().send_episode(record)
        if self.at_episode and self.first_episode is None:
            self.first_episode = record
            self.board.stop.set()


def _stopped_worker(tmp_path, links_args: dict, **overrides) -> tuple[dict, StoppedLinks, dict]:
    """One real worker (LKA) against a real replay core, stopped as ``links_args`` says; its
    summary, its links and the core's record of it."""
    cfg = load_run_config(overrides={**FAST, "actor.workers": 1, "train.run_dir": str(tmp_path), **overrides})
    builder = Builder(cfg)
    board = Board(cores=[builder.replay_core(0)])
    schema = builder.spec.schema
    net = build_q_network(schema.obs_shape, schema.n_actions, cfg.learner.hidden)
    board.weights = to_wire(net, 0, 0, 0)  # version 0; no learner publishes another
    links = StoppedLinks(board, "w0", **links_args)
    worker = builder.env_worker(0)
    try:
        summary = worker.run(links, 10_000).as_dict()
    finally:
        worker.close()
    return summary, links, board.cores[0].stats(all_actors=True)["actors"]["w0"]


@pytest.mark.parametrize("parallel", ["async", "sync"])
def test_a_stopped_worker_sends_the_n_step_items_it_still_held(tmp_path, parallel):
    """Stopped right after its first batch (a sync worker while it waits for the next weights):
    the items of the last n - 1 steps of each env, whose n rewards are not all known yet, go
    out in one last batch, so every env step made is stored (they used to be dropped)."""
    summary, links, stored = _stopped_worker(tmp_path, {"at_seq": 0}, **{"train.parallel": parallel,
                                                                         "learner.n_step": 3})
    assert [len(b) for b in links.sent] == [50 - 2, 2]  # the first window completes at step 3
    assert summary["env_steps"] == 50 and summary["batches"] == 2
    assert (stored["stored"], stored["env_steps"], stored["lost_items"]) == (50, 50, 0)
    assert (summary["undelivered_batches"], summary["undelivered_items"]) == (0, 0)


def test_a_stop_ends_the_batch_being_filled_and_sends_it(tmp_path):
    """The stop comes in the middle of a batch (at the first episode's end, before send_every
    steps): the worker steps no further and sends the shorter batch it holds."""
    summary, links, stored = _stopped_worker(tmp_path, {"at_episode": True}, **{"env.max_steps": 20})
    steps = links.first_episode.env_steps
    assert steps <= 20 < 50
    assert summary["env_steps"] == steps and [len(b) for b in links.sent] == [steps]
    assert (stored["stored"], stored["env_steps"], stored["lost_items"]) == (steps, steps, 0)


def test_pixel_run_learns_from_frames_held_once_each(tmp_path):
    """The paper's observation end to end: 4 x 100 x 100 uint8 frames from the env, on the
    wire, in a frame table that holds each frame about once, into the small CNN's updates."""
    cfg = load_run_config(overrides={**FAST, "env.scenario": "straight", "env.observation": "grayscale",
                                     "learner.cnn": "small", "train.env_steps": 600, "actor.send_every": 20,
                                     "replay.capacity": 2000, "train.run_dir": str(tmp_path)})
    result = train_inprocess(cfg)
    replay = result["replay"]
    assert replay["obs_shape"] == [4, 100, 100] and np.dtype(replay["obs_dtype"]) == np.uint8
    online = replay["tables"]["online"]
    assert online["inserted"] == 600 and replay["rejected"] == {}
    # About one new frame a step; episodes here are short (crashes under a random policy), and each
    # start stores its first frames, so well under the 8 that whole stacks would take.
    assert online["frames"]["per_item"] < 2.5 and online["frames"]["evicted_for_frames"] == 0
    assert result["updates"] > 0
    assert result["updates"] * 32 + result["learner"]["sample_rows_unused"] == replay["sampled_rows"]


def test_a_checkpoint_carries_its_observation_layout_and_eval_builds_that_env(tmp_path, capsys):
    """A run with env.alongside_features writes it into its checkpoints' metadata, so `laneshift eval`
    on a plain config builds the 88-float env the network reads (a run that left the option at its
    default writes nothing, and an older checkpoint without the key is evaluated as before)."""
    from laneshift.tools.cli import main
    from laneshift.wire import safetensors_loads

    cfg = load_run_config(overrides={**FAST, "env.scenario": "merge", "env.alongside_features": "true",
                                     "env.max_steps": 20, "train.env_steps": 400, "replay.min_size": 50,
                                     "train.run_dir": str(tmp_path)})
    train_inprocess(cfg)
    final = tmp_path / "checkpoints" / "final.safetensors"
    _, meta = safetensors_loads(final.read_bytes())
    assert meta["obs_shape"] == "88" and meta["alongside_features"] == "1" and "lane_features" not in meta
    capsys.readouterr()
    assert main(["eval", "--checkpoint", str(final), "--episodes", "1", "--max-steps", "5"]) == 0
    assert "from the checkpoint: scenario merge, alongside_features True" in capsys.readouterr().err
    # An explicit contrary choice is kept and refused, naming the fix.
    assert main(["eval", "--checkpoint", str(final), "--episodes", "1", "--set", "env.alongside_features=false"]) == 2
    assert "--set env.alongside_features=true" in capsys.readouterr().err
