"""TensorBoard output of the learner: every update metric and the loop's own, at env-step steps
that never go back (a resumed learner included), HParams at the end, and the greedy evaluation
during training (``train.eval_every``) on the LKA plant.

In process, no Ray, no zenoh: a Learner over fake links fed synthetic batches and episode
records, event files read back with TensorBoard's own reader.
Room: tests, unit. May import: the learner, the contract, the in-process runner, tensorboard's event reader,
tests/fakelinks.py.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from laneshift import wire
from laneshift.config import EnvConfig, load_run_config
from laneshift.envspec import EnvSpec
from laneshift.learner.dqn import METRIC_NAMES
from laneshift.learner.episodes import read_record
from laneshift.learner.loop import Learner
from laneshift.learner.periodic_eval import GreedyEval
from laneshift.learner.status import LearnerStatus
from laneshift.qnet import build_q_network

event_accumulator = pytest.importorskip("tensorboard.backend.event_processing.event_accumulator")

# tests/ is not a package and pytest runs with --import-mode=importlib: load the helper by path.
_spec = importlib.util.spec_from_file_location("laneshift_tests_fakelinks", Path(__file__).with_name("fakelinks.py"))
fakelinks = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = fakelinks
_spec.loader.exec_module(fakelinks)

torch.set_num_threads(1)

OBS, ACTIONS = (4,), 3
SPEC = EnvSpec("fake", wire.TransitionSchema(OBS, "<f4", ACTIONS), ())
SMALL = {"learner.hidden": "16", "learner.batch_size": 8, "learner.prefetch": 2, "learner.publish_every": 2,
         "learner.device": "cpu", "learner.checkpoint_every_s": 0}


class FakeLinks(fakelinks.QuietLinks):
    """LearnerLinks with a replay server that hands out random batches and reports ``env_steps``."""

    def __init__(self, env_steps: int = 0):
        super().__init__()
        self.env_steps, self.episodes = env_steps, []
        self.rng = np.random.default_rng(0)
        self.sampled = 0

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch:
        n = req.batch_size * req.num_batches
        self.sampled += n
        return wire.SampledBatch(
            obs=self.rng.standard_normal((n, *OBS), dtype=np.float32), action=self.rng.integers(0, ACTIONS, n),
            reward=self.rng.standard_normal(n, dtype=np.float32),
            next_obs=self.rng.standard_normal((n, *OBS), dtype=np.float32),
            terminated=np.zeros(n, np.uint8), steps=np.ones(n, np.uint8), is_demo=np.zeros(n, np.uint8),
            index=np.arange(n), weight=np.ones(n, np.float32), num_batches=req.num_batches, info={})

    def replay_stats(self) -> dict:
        return {"tables": {"online": {"size": min(self.env_steps, 1000), "capacity": 1000}},
                "actors": {"w0": {"last_version": 0}, "w1": {"last_version": 0}},
                "actors_total": {"env_steps": self.env_steps, "lost_items": 0},
                "rates": {"inserts_per_s": 10.0, "samples_per_s": 80.0}, "demo_share_buffer": 0.0,
                "demo_share_recent_samples": 0.0, "sampled_rows": self.sampled}

    def take_episodes(self) -> list[wire.EpisodeRecord | wire.WireError]:
        out, self.episodes = self.episodes, []
        return [read_record(payload) for payload in out]  # decoded, as the links hand them over

    def episode(self, actor: str, env_steps: int) -> None:
        self.episodes.append(wire.encode_json({"actor": actor, "return": -1.5, "length": 40, "crashed": False,
                                               "on_target_lane": True, "weights_version": 0, "phase": 0,
                                               "env_steps": env_steps, "epsilon": 0.5}))


def _learner(run_dir, links, **overrides) -> Learner:
    cfg = load_run_config(overrides={**SMALL, "train.run_dir": str(run_dir), **overrides})
    return Learner(cfg, SPEC, links, threading.Event())


def _drive(learner: Learner, links: FakeLinks, rounds: int, replay_steps: int, actor_steps: int) -> None:
    """``rounds`` log intervals: the replay server's count grows by ``replay_steps`` each, and each
    worker (w0, w1) reports an episode ``actor_steps`` further on."""
    for _ in range(rounds):
        links.env_steps += replay_steps
        for actor in ("w0", "w1"):
            links.episode(actor, learner.episodes.worker_steps.get(actor, 0) + actor_steps)
        learner._async_step()
        learner._log()


def _stopped_run(run_dir, replay_steps: int = 100) -> Learner:
    """A learner driven for 4 log intervals (the replay server's count growing by ``replay_steps``
    each) and finished: its state in ``run_dir`` for a resumed learner to restore."""
    links = FakeLinks()
    learner = _learner(run_dir, links)
    learner.publish()
    _drive(learner, links, rounds=4, replay_steps=replay_steps, actor_steps=40)
    learner._finish()
    return learner


def _scalars(tb_dir) -> event_accumulator.EventAccumulator:
    acc = event_accumulator.EventAccumulator(str(tb_dir), size_guidance={event_accumulator.SCALARS: 0})
    acc.Reload()
    return acc


def _steps(acc, tag: str) -> list[int]:
    return [e.step for e in acc.Scalars(tag)]


def test_every_metric_at_env_step_steps_that_never_go_back_across_a_resume(tmp_path):
    learner = _stopped_run(tmp_path)
    first_end = learner.env_steps
    assert first_end == 400  # the replay server's count (ahead of the episode reports here)

    # --resume: the learner state brings the env-step count back even while the replay server
    # (here: a fresh one) and the workers report less.
    links2 = FakeLinks(env_steps=0)
    again = _learner(tmp_path, links2)
    assert again.restored_from and again.env_steps == first_end and again.agent.updates == learner.agent.updates
    again.publish()
    _drive(again, links2, rounds=3, replay_steps=50, actor_steps=30)
    links2.env_steps = first_end + 500  # the replay server catches up, then leads
    _drive(again, links2, rounds=2, replay_steps=100, actor_steps=30)
    again._finish()

    acc = _scalars(tmp_path / "tb")
    tags = set(acc.Tags()["scalars"])
    expected = ({f"learner/{k}" for k in (*METRIC_NAMES, "updates", "updates_per_s", "version", "phase")}
                | {f"train/{k}" for k in ("env_steps_per_s", "episodes", "return_mean", "length_mean", "crash_rate",
                                          "achievement_rate", "epsilon")}
                | {"actors/version_lag_w0", "actors/version_lag_w1", "actors/version_lag_max",
                   "replay/size", "replay/fill", "replay/demo_share_buffer", "replay/demo_share_samples",
                   "replay/sampled_rows", "replay/env_steps", "replay/lost_items", "replay/inserts_per_s",
                   "replay/samples_per_s"}
                | {f"episode/{k}" for k in ("return", "length", "crashed", "on_target_lane", "epsilon", "version_lag")})
    assert expected <= tags, sorted(expected - tags)
    for tag in tags:
        steps = _steps(acc, tag)
        assert steps == sorted(steps), (tag, steps)
    # Both runs' points are there (a step going back would make the reader drop the older ones).
    loss_steps = _steps(acc, "learner/loss")
    assert len(loss_steps) == 4 + 1 + 5 + 1  # each _log, and _finish's
    assert loss_steps[:5] == [100, 200, 300, 400, 400]
    assert min(loss_steps[5:]) == first_end and loss_steps[-1] == first_end + 700
    assert _steps(acc, "learner/updates") == loss_steps
    # The update count is a value, not the axis.
    updates = [e.value for e in acc.Scalars("learner/updates")]
    assert updates == sorted(updates) and updates[-1] == again.agent.updates
    grad = [e.value for e in acc.Scalars("learner/grad_norm")]
    assert all(np.isfinite(grad)) and max(grad) > 0
    assert [e.value for e in acc.Scalars("learner/margin_loss")] == [0.0] * len(loss_steps)

    # metrics.jsonl keeps kind, env_steps, updates and time; "step" is TensorBoard's step.
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    learner_records = [r for r in records if r["kind"] == "learner"]
    assert all({"env_steps", "updates", "time", "step", *METRIC_NAMES} <= set(r) for r in learner_records)
    assert [r["step"] for r in learner_records] == loss_steps
    episodes = [r for r in records if r["kind"] == "episode"]
    assert len(episodes) == 2 * (4 + 5) and [r["episode"] for r in episodes] == list(range(1, 19))


def test_a_resumed_learner_counts_its_rates_from_where_it_restarted(tmp_path):
    # The rates of the first status after a resume once counted the restored updates and env steps
    # as made in that interval (6,171 updates/s and 3,268 env steps/s in a pixel run making 35).
    learner = _stopped_run(tmp_path)
    assert learner.env_steps == 400 and learner.agent.updates > 0

    again = _learner(tmp_path, FakeLinks(env_steps=400))  # the replay server kept its count
    again._log()  # no update and no env step since the restart
    assert again.last_status.updates == learner.agent.updates and again.last_status.env_steps == 400
    assert again.last_status.updates_per_s == 0.0 and again.last_status.env_steps_per_s == 0.0


def test_a_resumed_learner_evaluates_at_its_next_multiple_of_eval_every(tmp_path):
    # It once evaluated at once at the resume point, then again at the next multiple.
    learner = _stopped_run(tmp_path, replay_steps=110)
    assert learner.env_steps == 440

    cfg = load_run_config(overrides={**SMALL, "train.run_dir": str(tmp_path), "train.eval_every": 100})
    again = Learner(cfg, SPEC, FakeLinks(env_steps=440), threading.Event(), evaluate=lambda batch: {})
    assert again.env_steps == 440 and again.evaluator.next_at == 500
    assert not again.evaluator.due(440) and again.evaluator.due(500)
    again.metrics.close()
    new_cfg = load_run_config(overrides={**SMALL, "train.run_dir": str(tmp_path / "new"), "train.eval_every": 100})
    fresh = Learner(new_cfg, SPEC, FakeLinks(), threading.Event(), evaluate=lambda batch: {})
    assert fresh.evaluator.next_at == 100  # a new run: the first multiple
    fresh.metrics.close()


@pytest.mark.parametrize("fade_steps, expected", [(0, [1.0, 0.5, 0.0, 0.0]), (250, [1.0, 0.0, 0.0, 0.0])])
def test_the_imitation_losses_fade_with_the_env_steps_and_the_scale_is_logged(tmp_path, fade_steps, expected):
    links = FakeLinks()
    learner = _learner(tmp_path, links, **{"train.env_steps": 1000, "learner.bc_loss_weight": 1.0,
                                           "learner.imitation_final": 0.0, "learner.imitation_fade_steps": fade_steps})
    learner.publish()
    assert learner.agent.imitation_scale == 1.0
    scales = []
    for steps in (0, 500, 1000, 2000):
        links.env_steps = steps
        learner._async_step()
        learner._log_when_due(0.0)
        scales.append(learner.agent.imitation_scale)
    learner._finish()
    assert scales == pytest.approx(expected)
    logged = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    # Each learner line holds the scale its interval trained with: the one set at the line before.
    assert [r["imitation_scale"] for r in logged if r["kind"] == "learner"][1:4] == pytest.approx(expected[:3])
    assert "learner/imitation_scale" in _scalars(tmp_path / "tb").Tags()["scalars"]


def test_hparams_hold_the_flattened_config_and_final_metrics(tmp_path):
    from tensorboard.plugins.hparams import plugin_data_pb2

    links = FakeLinks()
    learner = _learner(tmp_path, links, **{"learner.lr": 0.001})
    learner.publish()
    _drive(learner, links, rounds=2, replay_steps=100, actor_steps=50)
    learner._finish()

    acc = event_accumulator.EventAccumulator(str(tmp_path / "tb" / "hparams"))
    acc.Reload()
    content = acc.PluginTagToContent("hparams")
    start = plugin_data_pb2.HParamsPluginData.FromString(content["_hparams_/session_start_info"]).session_start_info
    hp = start.hparams
    assert hp["learner.lr"].number_value == pytest.approx(0.001)
    assert hp["learner.hidden"].string_value == "16"
    assert hp["env.scenario"].string_value == "straight"
    assert hp["train.stop_return"].string_value == "inf"  # not a number TensorBoard's JSON could carry
    assert hp["learner.double"].bool_value is True
    experiment = plugin_data_pb2.HParamsPluginData.FromString(content["_hparams_/experiment"]).experiment
    metrics = {m.name.tag for m in experiment.metric_infos}
    assert {"final/return_mean", "final/crash_rate", "final/updates", "final/env_steps"} <= metrics
    final = {tag: acc.Scalars(tag)[-1] for tag in acc.Tags()["scalars"]}
    assert final["final/env_steps"].value == 200 and final["final/env_steps"].step == 200
    # The text config stays too.
    main = event_accumulator.EventAccumulator(str(tmp_path / "tb"))
    main.Reload()
    assert "config/text_summary" in main.Tags()["tensors"]


def test_rehearsal_phase1_logs_under_pretrain_at_update_steps(tmp_path):
    links = FakeLinks()
    learner = _learner(tmp_path, links, **{"replay.demo_mode": "rehearsal", "learner.phase1_updates": 1000})
    assert learner.phase == 1
    for _ in range(3):
        learner._updates(links.sample(wire.SampleRequest(8, 2)))
        learner._log()
    learner.metrics.close()
    acc = _scalars(tmp_path / "tb")
    assert _steps(acc, "pretrain/learner/loss") == [2, 4, 6]
    assert not any(t.startswith("learner/") for t in acc.Tags()["scalars"])


class _DemoLinks(FakeLinks):
    """Demo rows whose next observations are NaN (none where the request asks for none, as the
    replay answers), and the agent's td_loss and the request's next_obs recorded at each sample."""

    def __init__(self, learner_ref: list):
        super().__init__()
        self.learner_ref, self.td_loss_seen, self.next_obs_asked = learner_ref, [], []

    def sample(self, req: wire.SampleRequest) -> wire.SampledBatch:
        if self.learner_ref:
            self.td_loss_seen.append(self.learner_ref[0].agent.td_loss)
        self.next_obs_asked.append(req.next_obs)
        batch = super().sample(req)
        n = len(batch.action)
        next_obs = np.full((n, *OBS), np.nan, np.float32) if req.next_obs else None
        return dataclasses.replace(batch, next_obs=next_obs, is_demo=np.ones(n, np.uint8))


def test_phase1_with_phase1_td_false_trains_the_imitation_alone_then_phase2_learns_with_td(tmp_path):
    holder: list = []
    links = _DemoLinks(holder)
    learner = _learner(tmp_path, links, **{"replay.demo_mode": "rehearsal", "learner.phase1_updates": 40,
                                           "learner.bc_loss_weight": 1.0, "learner.phase1_td": False})
    holder.append(learner)
    learner._rehearsal_phase1()
    # The NaN next observations never reached an update: the network stayed finite.
    assert learner.agent.updates == 40 and learner.phase == 2
    assert all(torch.isfinite(p).all() for p in learner.agent.online.parameters())
    assert links.td_loss_seen and not any(links.td_loss_seen)
    assert links.next_obs_asked and not any(links.next_obs_asked)  # the replies left them out
    assert learner.agent.td_loss  # phase 2 trains the TD loss again
    assert (tmp_path / "checkpoints" / "phase1.safetensors").is_file()
    learner.metrics.close()


def _episodes_of(env_cfg: EnvConfig, episodes: int):
    """The EvaluatePolicy the builder hands the learner: ``episodes`` greedy episodes on the env."""
    from laneshift.actors.evaluation import GreedyPolicy, evaluate_policy

    return lambda batch: evaluate_policy(lambda env: GreedyPolicy(batch), env_cfg, episodes, seed=0)


def test_greedy_eval_runs_a_copy_of_the_network_on_its_own_thread():
    from laneshift.actors.envs import spec_of

    env_cfg = EnvConfig(scenario="lka", max_steps=20)
    schema = spec_of(env_cfg).schema
    net = build_q_network(schema.obs_shape, schema.n_actions, (8,))
    ev = GreedyEval(_episodes_of(env_cfg, 2), every=100, obs_shape=schema.obs_shape,
                    n_actions=schema.n_actions, hidden=(8,), dueling=False)
    assert not ev.due(99) and ev.due(100)
    ev.start(net, 250, updates=7, version=3)
    assert ev.next_at == 300 and not ev.due(299)
    ev._thread.join(30)
    result = ev.take()
    assert result is not None and ev.take() is None and ev.failed is None
    assert result["env_steps"] == 250 and result["updates"] == 7 and result["version"] == 3
    assert result["episodes"] == 2 and 0.0 <= result["survival_rate"] <= 1.0
    assert "achievement_rate" not in result  # LKA: no target lane
    assert result["length_mean"] <= 20
    ev.close()


def test_a_running_eval_is_cancelled_at_close():
    from laneshift.actors.envs import spec_of

    env_cfg = EnvConfig(scenario="lka")
    schema = spec_of(env_cfg).schema
    ev = GreedyEval(_episodes_of(env_cfg, 10_000), every=1, obs_shape=schema.obs_shape,
                    n_actions=schema.n_actions, hidden=(8,), dueling=False)
    ev.start(build_q_network(schema.obs_shape, schema.n_actions, (8,)), 1)
    began = time.monotonic()
    ev.close(timeout=0)
    assert not ev.running and time.monotonic() - began < 5
    assert ev.take() is None and ev.failed is None


def test_eval_during_training_on_the_lka_plant(tmp_path):
    from laneshift.deploy.inprocess import train_inprocess

    fast = {"env.scenario": "lka", "env.max_steps": 50, "actor.send_every": 50, "learner.hidden": "32,32",
            "learner.batch_size": 32, "learner.publish_every": 5, "replay.min_size": 100,
            "replay.samples_per_insert": 4, "replay.spi_tolerance": 512, "train.env_steps": 2000,
            "train.eval_every": 400, "train.periodic_eval_episodes": 2, "train.run_dir": str(tmp_path)}
    began = time.monotonic()
    train_inprocess(load_run_config(overrides=fast))
    assert time.monotonic() - began < 120
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    evals = [r for r in records if r["kind"] == "eval"]
    assert evals, "no greedy evaluation finished during training"
    assert all(r["episodes"] == 2 and 0.0 <= r["survival_rate"] <= 1.0 for r in evals)
    steps = [r["env_steps"] for r in evals]
    assert steps == sorted(set(steps)) and steps[0] >= 400
    acc = _scalars(tmp_path / "tb")
    assert _steps(acc, "eval/survival_rate") == steps
    assert {"eval/return_mean", "eval/length_mean"} <= set(acc.Tags()["scalars"])
    for tag in acc.Tags()["scalars"]:
        s = _steps(acc, tag)
        assert s == sorted(s), tag


def _status(**given) -> LearnerStatus:
    """A LearnerStatus with ``given`` and every other field 0 (None where it may be None)."""
    values = {}
    for f in dataclasses.fields(LearnerStatus):
        if f.name not in given and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            values[f.name] = None if "None" in str(f.type) else 0
    return LearnerStatus(**{**values, **given})


def test_the_status_names_every_update_metric_and_every_prometheus_metric_is_a_status_field():
    from laneshift.learner.prometheus import COUNTERS, GAUGES

    names = [f.name for f in dataclasses.fields(LearnerStatus)]
    assert set(METRIC_NAMES) <= set(names)
    assert set(COUNTERS) | set(GAUGES) <= set(names)


def test_learner_prometheus_endpoint_serves_its_status():
    """learner.metrics_port: /metrics in the Prometheus text format, counters as _total, the
    status of the newest log interval, process metrics; closed with the learner's finish."""
    import urllib.request

    from laneshift.learner.prometheus import LearnerMetricsServer

    server = LearnerMetricsServer("127.0.0.1", 0)
    try:
        server.update(_status(updates=12, env_steps=10, episodes=7, loss=0.25, q_mean=-1.5, version=3, phase=0,
                              version_lag={"w0": 1, "w1": 0}, return_mean=None, sample_wait_s=1.5,
                              sample_wait_share=0.04), env_steps=3400)  # the learner's count, not the replay's
        text = urllib.request.urlopen(f"http://127.0.0.1:{server.port}/metrics", timeout=5).read().decode()
    finally:
        server.close()
    lines = {line.split(" ")[0]: line.split(" ")[1] for line in text.splitlines() if line and not line.startswith("#")}
    assert float(lines["laneshift_learner_updates_total"]) == 12
    assert float(lines["laneshift_learner_env_steps_total"]) == 3400
    assert float(lines["laneshift_learner_loss"]) == 0.25
    assert float(lines['laneshift_learner_version_lag{worker="w0"}']) == 1
    assert float(lines["laneshift_learner_sample_wait_seconds_total"]) == 1.5  # which side bounds the run
    assert float(lines["laneshift_learner_sample_wait_ratio"]) == 0.04
    assert "laneshift_learner_episode_return_mean" not in lines  # None: not reported, not 0
    assert "laneshift_learner_updates_total counter" in text and "process_cpu_seconds_total" in lines


def test_the_wait_for_the_replay_to_fill_is_not_counted_as_the_workers_bounding_the_run(tmp_path):
    """Until its first batch the learner waits for replay.min_size items, by design: the run's
    ``training_wait_s`` starts at the first batch, ``sample_wait_s`` (every interval's share) at the start."""

    class Filling(FakeLinks):
        def __init__(self) -> None:
            super().__init__()
            # From the first request, not from here: under load building the learner took half of it.
            self.refuse_until: float | None = None

        def sample(self, req: wire.SampleRequest):
            if self.refuse_until is None:
                self.refuse_until = time.monotonic() + 0.6
            if time.monotonic() < self.refuse_until:
                err = wire.WireError("rate_limited", "filling")
                err.retry_after_ms = 5  # type: ignore[attr-defined]
                return err
            return super().sample(req)

    links = Filling()
    learner = _learner(tmp_path, links)
    learner.publish()
    while learner.agent.updates < 6:
        learner._async_step()
    status = learner._status()
    learner._finish()
    assert status.sample_wait_s >= 0.5  # the fill, waited by the update thread
    assert status.training_s is not None and status.training_wait_s < 0.25


def test_the_summarys_final_greedy_evaluation_is_in_tensorboard_and_metrics_jsonl(tmp_path):
    from laneshift.deploy.summary import record_final_eval

    (tmp_path / "tb").mkdir()
    record_final_eval(tmp_path, 30_000, {"episodes": 10, "survival_rate": 0.9, "achievement_rate": 0.8,
                                         "return_mean": 12.5, "length_mean": 290.0, "return_std": 1.0})
    acc = event_accumulator.EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    scalars = {tag: acc.Scalars(tag)[-1] for tag in acc.Tags()["scalars"]}
    assert set(scalars) == {"final_eval/survival_rate", "final_eval/achievement_rate", "final_eval/return_mean",
                            "final_eval/length_mean"}
    assert scalars["final_eval/achievement_rate"].value == pytest.approx(0.8)
    assert scalars["final_eval/achievement_rate"].step == 30_000
    (line,) = (tmp_path / "metrics.jsonl").read_text().splitlines()
    rec = json.loads(line)
    assert rec["kind"] == "final_eval" and rec["env_steps"] == 30_000 and rec["episodes"] == 10


def test_a_long_run_evaluates_greedily_during_training_unless_told_otherwise():
    from laneshift.config import AUTO_EVAL_FROM

    assert load_run_config().train.eval_interval == 0  # 20,000 env steps: short, no evaluation
    long_run = load_run_config(overrides={"train.env_steps": AUTO_EVAL_FROM})
    assert long_run.train.eval_every == -1 and long_run.train.eval_interval == AUTO_EVAL_FROM // 10
    assert load_run_config(overrides={"train.env_steps": 10**6, "train.eval_every": 0}).train.eval_interval == 0
    assert load_run_config(overrides={"train.eval_every": 500}).train.eval_interval == 500


def test_a_failed_event_write_is_counted_never_blocks_and_a_new_file_takes_over_once_there_is_room(
        tmp_path, monkeypatch):
    """A full disk: tensorboardX's own writer thread died on such a write and the learner then
    blocked for ever on its full queue (the whole run stalled). Here every event lost is counted,
    no call waits, and after ``retry_s`` a new event file carries on."""
    import errno

    from laneshift.learner import metrics

    full = [True]

    class FillingDisk(metrics.EventsWriter):
        def _write_serialized_event(self, event_str):
            if full[0]:
                raise OSError(errno.ENOSPC, "No space left on device")
            super()._write_serialized_event(event_str)

    monkeypatch.setattr(metrics, "EventsWriter", FillingDisk)
    now = [0.0]
    events = metrics.EventFile(tmp_path / "tb", retry_s=30.0, clock=lambda: now[0])
    started = time.monotonic()
    for step in range(100):  # far more than tensorboardX's queue of 10
        events.add_scalar("learner/loss", float(step), step)
    assert time.monotonic() - started < 5.0
    assert events.failures == 100
    full[0] = False
    now[0] = 29.0  # not yet: still counted, no file opened
    events.add_scalar("learner/loss", 100.0, 100)
    assert events.failures == 101
    now[0] = 31.0
    for step in range(101, 106):
        events.add_scalar("learner/loss", float(step), step)
    events.close()
    assert events.failures == 101
    acc = event_accumulator.EventAccumulator(str(tmp_path / "tb"))
    acc.Reload()
    assert [e.step for e in acc.Scalars("learner/loss")] == [101, 102, 103, 104, 105]


def test_the_metrics_logs_failures_count_lost_lines_and_lost_events(tmp_path, monkeypatch):
    from laneshift.learner.metrics import MetricsLog

    log = MetricsLog(tmp_path)
    log.write("learner", 1, {"loss": 0.5, "updates": 3})  # two scalars and one line

    def refuse(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(log._jsonl, "write", refuse)
    monkeypatch.setattr(log.tb, "_file", lambda: None)  # no event file can be opened
    log.write("learner", 2, {"loss": 0.4, "updates": 4})
    assert (log.jsonl_failures, log.tb.failures, log.write_failures) == (1, 2, 3)
    log.close()
