"""Stacked frames held once per frame in the replay server (``replay_server/frames.py``): stored as
whole stacks, the paper's 4 x 100 x 100 observations would keep every frame 8 times (obs, next_obs).

Each actor drives synthetic episodes whose frames are random images; its observations are the
shifting 4-frame stacks a frame-stacking env makes (reset: the first frame repeated; with
``env.frame_interval`` k, frames k steps apart), sent as n-step items in batches, two actors
interleaved. Every sampled item must be exactly the stacks that were sent for its key, whatever
the frame ring's size (a too small ring drops the oldest items early, counted, and never returns
a wrong frame), through checkpoints and in the demo table; about one frame an item is stored.
Room: tests, unit. May import: numpy, pytest, laneshift (wire, config, replay_server).
"""

from __future__ import annotations

import numpy as np
import pytest

from laneshift import wire
from laneshift.config import ReplayConfig
from laneshift.replay_server.checkpoint import restore_checkpoint, write_checkpoint
from laneshift.replay_server.core import ReplayCore
from laneshift.replay_server.frames import FrameRingTable, dedup_stacks, fixed_stack_views
from laneshift.replay_server.storage import DemoTable
from laneshift.wire import SampleRequest, TransitionBatch, TransitionSchema

STACK, SIDE = 4, 12
SCHEMA = TransitionSchema(obs_shape=(STACK, SIDE, SIDE), obs_dtype="uint8", n_actions=9)


def episode_items(rng: np.random.Generator, steps: int, n_step: int,
                  interval: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """One episode's (obs, next_obs) stacks of n-step items: ``[steps, S, H, W]`` each."""
    frames = rng.integers(0, 256, size=(steps + 1, SIDE, SIDE), dtype=np.uint8)
    reach = (STACK - 1) * interval  # steps from a stack's oldest frame to its newest
    padded = np.concatenate([np.repeat(frames[:1], reach, axis=0), frames])  # reset: first frame repeated
    stacks = np.stack([padded[t:t + reach + 1:interval] for t in range(steps + 1)])
    nxt = np.minimum(np.arange(steps) + n_step, steps)  # n steps ahead, cut at the episode's end
    return stacks[:steps], stacks[nxt]


class Actor:
    def __init__(self, name: str, seed: int, n_step: int, interval: int = 1, episode_steps: tuple = (5, 40)):
        self.name, self.rng, self.n_step, self.seq, self.steps = name, np.random.default_rng(seed), n_step, 0, 0
        self.interval, self.episode_steps = interval, episode_steps
        self.obs = np.zeros((0, STACK, SIDE, SIDE), np.uint8)
        self.next_obs = self.obs.copy()

    def batch(self, rows: int) -> bytes:
        while len(self.obs) < rows:
            o, n = episode_items(self.rng, int(self.rng.integers(*self.episode_steps)), self.n_step, self.interval)
            self.obs, self.next_obs = np.concatenate([self.obs, o]), np.concatenate([self.next_obs, n])
        obs, nxt = self.obs[:rows], self.next_obs[:rows]
        self.obs, self.next_obs = self.obs[rows:], self.next_obs[rows:]
        self.steps += rows
        msg = wire.encode_transitions(TransitionBatch.from_arrays(
            actor=self.name, seq=self.seq, weights_version=0, phase=0, env_steps=self.steps, obs=obs,
            action=np.zeros(rows), reward=np.zeros(rows, np.float32), next_obs=nxt, terminated=np.zeros(rows),
            truncated=np.zeros(rows)))
        self.seq += 1
        return msg, obs, nxt


def run(core: ReplayCore, batches: int, rows: int = 25, n_step: int = 1,
        names: tuple[str, str] = ("w0", "w1"), **episodes) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Two interleaved actors (each numbering its batches from seq 0); returns what was sent, by item key."""
    actors = [Actor(names[0], 1, n_step, **episodes), Actor(names[1], 2, n_step, **episodes)]
    sent: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for b in range(batches):
        msg, obs, nxt = actors[b % 2].batch(rows)
        first = core.online.inserted
        assert core.ingest(msg, actors[b % 2].name) is None
        for i in range(rows):
            sent[first + i] = (obs[i], nxt[i])
    return sent


def make_core(capacity: int = 400, **kw) -> ReplayCore:
    return ReplayCore(ReplayConfig(capacity=capacity, min_size=1, samples_per_insert=0.0, **kw), SCHEMA)


def check_samples(core: ReplayCore, sent: dict, draws: int = 20) -> None:
    for _ in range(draws):
        out = core.sample(SampleRequest(batch_size=32, num_batches=1))
        assert isinstance(out, wire.SampledBatch), out
        for i, key in enumerate(out.index):
            assert core.online.tail <= key < core.online.inserted
            obs, nxt = sent[int(key)]
            assert np.array_equal(out.obs[i], obs) and np.array_equal(out.next_obs[i], nxt)


@pytest.mark.parametrize("n_step", [1, 3])
def test_sampled_stacks_are_the_sent_ones_with_about_one_new_frame_an_item(n_step):
    core = make_core()
    assert isinstance(core.online, FrameRingTable)
    sent = run(core, batches=60, n_step=n_step)  # 1,500 items through a 400-item table: it wraps
    check_samples(core, sent)
    frames = core.stats()["tables"]["online"]["frames"]
    # One new frame per step, 4 more per episode (reset + its stacks), a few re-stored per interleave.
    assert frames["per_item"] < 1.6, frames
    assert frames["evicted_for_frames"] == 0 and core.online.size == 400
    stacks_bytes = 2 * 400 * STACK * SIDE * SIDE
    assert core.online.store.frames.nbytes <= stacks_bytes / 4 + 1  # 2 frames an item vs 8


@pytest.mark.parametrize("interval", [1, 4])
def test_long_episodes_store_one_frame_an_item_whatever_the_spacing_and_the_interleave(interval):
    # The pixel runs' shape: n = 10, two actors, 32-row batches, episodes of 150-300 steps. Frames
    # k steps apart share nothing with the previous step's stack, and each actor's rows reuse frames
    # older than the other actor's last rows: a floor made of each row's oldest frame forbade
    # that, and 6.7 frames an item were stored with k = 4 (a 140,000-item table held 43,000).
    core = make_core(capacity=2_000)
    sent = run(core, batches=200, rows=32, n_step=10, interval=interval, episode_steps=(150, 300))
    check_samples(core, sent)
    frames = core.stats()["tables"]["online"]["frames"]
    assert frames["per_item"] < 1.05 and frames["evicted_for_frames"] == 0, frames
    assert core.online.size == 2_000


def test_a_small_frame_ring_drops_the_oldest_items_early_and_counts_them():
    core = make_core(frames_per_item=1.0)
    sent = run(core, batches=60)
    table = core.online
    assert table.evicted_for_frames > 0 and table.size < table.capacity
    assert table.size + table.evicted_for_frames <= table.inserted
    check_samples(core, sent)  # what is left is exact
    assert core.stats()["tables"]["online"]["frames"]["evicted_for_frames"] == table.evicted_for_frames


def test_prioritized_sampling_never_draws_an_item_dropped_for_its_frames():
    core = make_core(frames_per_item=1.0, sampler="prioritized")
    sent = run(core, batches=60)
    assert core.online.evicted_for_frames > 0
    check_samples(core, sent, draws=40)
    gone = np.arange(core.online.inserted - core.online.capacity, core.online.tail) % core.online.capacity
    assert (core.selector.priority_of(core.demo.size + gone) == 0).all()


def test_checkpoint_round_trip_keeps_every_item_and_its_frames(tmp_path):
    core = make_core()
    sent = run(core, batches=30)
    info = write_checkpoint(core, tmp_path / "ckpt")
    assert info["items"] == core.online.size == 400
    fresh = make_core()
    assert restore_checkpoint(fresh, tmp_path / "ckpt") == 400
    # Restored items are renumbered 0..n-1 oldest first.
    old_keys = np.arange(core.online.tail, core.online.inserted)
    renumbered = {new: sent[int(old)] for new, old in enumerate(old_keys)}
    check_samples(fresh, renumbered)
    more = run(fresh, batches=4, names=("w2", "w3"))  # it goes on inserting after a restore (w0's seq 0 is held)
    assert fresh.online.inserted == 500 and set(more) == set(range(400, 500))


def test_demo_table_holds_each_distinct_frame_once():
    obs, nxt = episode_items(np.random.default_rng(0), 200, 1)
    frames, obs_keys, next_keys = dedup_stacks(obs, nxt)
    assert len(frames) == 201  # the episode's frames, once each
    assert np.array_equal(frames[obs_keys], obs) and np.array_equal(frames[next_keys], nxt)
    o, n = fixed_stack_views(obs, nxt)
    demo = DemoTable(obs=o, action=np.zeros(200, np.int64), reward=np.zeros(200, np.float32), next_obs=n,
                     terminated=np.zeros(200, np.uint8), sha256="s", metadata={})
    assert demo.nbytes < (obs.nbytes + nxt.nbytes) / 5
    rows = np.array([0, 3, 199])
    sub = demo.subset(rows)
    assert np.array_equal(sub.obs[np.arange(3)], obs[rows]) and np.array_equal(sub.next_obs[np.arange(3)], nxt[rows])
    assert demo.digest() == demo.digest()
    with pytest.raises(ValueError):
        o.store.frames[0, 0, 0] = 1  # read-only, like every demo array
