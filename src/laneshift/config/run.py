"""How a run is wired: the ``transport``, ``train`` and ``deploy`` sections, and ``RunConfig``, which
groups them with the components' sections (``.sections``) and checks the rules that span
sections (a sample request within the rate limiter's slack, a message within zenoh's limit).

Room: the contract (shared by every process). May import: the standard library, ``.checks`` and
``.sections``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping

from .checks import NAME, ConfigError, _check, _check_choices
from .sections import ROADS, ActorConfig, EnvConfig, LearnerConfig, ReplayConfig


@dataclass(frozen=True)
class TransportConfig:
    """zenoh: every process is a client of one router (measured: peers behind a router get nothing)."""

    router: str = "tcp/127.0.0.1:7447"  # the endpoint clients connect to and the router listens on
    run_id: str = "run"  # namespace in every key expression: laneshift/<run_id>/...
    timeout_s: float = 5.0  # query timeout
    # zenoh drops a received message larger than this before buffering it (hostile or broken
    # senders cannot balloon the router's or the replay server's memory). 0 = sized from the run
    # (RunConfig.max_message_bytes): twice its largest message (a sample reply), at least 16 MiB.
    max_message_mb: float = 0.0
    # How long a process waits for its router before it gives up with one line naming it
    # (0 = forever: services may start before the router, and WaitReporter says what they wait for).
    connect_timeout_s: float = 0.0

    def __post_init__(self) -> None:
        _check(self.router.startswith(("tcp/", "udp/", "unixsock-stream/")), "transport.router",
               "must be a zenoh endpoint like tcp/127.0.0.1:7447", self.router)
        _check(bool(NAME.fullmatch(self.run_id)), "transport.run_id", "must match [A-Za-z0-9_-]{1,64}", self.run_id)
        _check(self.timeout_s > 0, "transport.timeout_s", "must be > 0", self.timeout_s)
        _check(self.max_message_mb >= 0, "transport.max_message_mb", "must be >= 0 (0 = sized from the run)",
               self.max_message_mb)
        _check(self.connect_timeout_s >= 0, "transport.connect_timeout_s", "must be >= 0 (0 = wait forever)",
               self.connect_timeout_s)


#: Runs at least this long evaluate greedily ten times during training unless told otherwise
#: (train.eval_every = -1): long enough that 10 x 5 episodes cost under 1 % of the run.
AUTO_EVAL_FROM = 100_000


@dataclass(frozen=True)
class TrainConfig:
    """The run as a whole: budget, parallel mode and where things go."""

    env_steps: int = 20_000  # total env steps over all workers (after rehearsal phase 1)
    parallel: Literal["async", "sync"] = "async"  # async | sync (MATLAB parallel training modes)
    run_dir: str = "runs/latest"  # checkpoints, metrics.jsonl, TensorBoard files, the resolved config and logs
    log_every_s: float = 2.0  # seconds between the launcher's progress lines
    eval_episodes: int = 10  # greedy episodes in the final summary (0 = skip)
    # Greedy evaluation during training, every this many env steps (0 = off; -1 = a tenth of
    # train.env_steps for runs of at least 100,000 env steps (AUTO_EVAL_FROM), else off): the learner copies its
    # current network to a background thread with its own env and logs survival, achievement and
    # return to TensorBoard (eval/*) and metrics.jsonl (kind "eval"); training goes on meanwhile.
    # The end of the run evaluates once more if a multiple was passed since (waiting up to 10 s).
    eval_every: int = -1
    periodic_eval_episodes: int = 5  # greedy episodes per evaluation during training (train.eval_every)
    validation_seed: int = 200_000  # its episode i is reset with seed validation_seed + i (studies test from 100,000)
    # MATLAB's stop criterion: end the run as soon as an episode's return reaches this (inf = never).
    stop_return: float = math.inf
    # Scripted episodes in the default demo shard (demo modes without replay.demo_paths);
    # 0 = just enough for the demo region (retention) or 2,000 transitions (rehearsal).
    demo_episodes: int = 0
    # The default demo shard keeps only the scripted driver's episodes that end alive on the target lane
    # (it drives further seeds until it has its count): the demonstrations never show a wait that fails.
    demo_achieved_only: bool = False
    seed: int = 0  # the default demo shard's episode seeds start at seed + 10,000; `experiment` commands give it to every component

    def __post_init__(self) -> None:
        _check_choices(self, "train")
        _check(self.demo_episodes >= 0, "train.demo_episodes", "must be >= 0 (0 = sized by need)",
               self.demo_episodes)
        _check(self.env_steps >= 1, "train.env_steps", "must be >= 1", self.env_steps)
        _check(self.log_every_s > 0, "train.log_every_s", "must be > 0", self.log_every_s)
        _check(self.eval_episodes >= 0, "train.eval_episodes", "must be >= 0", self.eval_episodes)
        _check(self.eval_every >= -1, "train.eval_every", "must be >= 0 (0 = off) or -1 (a tenth of long runs)",
               self.eval_every)
        _check(self.periodic_eval_episodes >= 1, "train.periodic_eval_episodes", "must be >= 1",
               self.periodic_eval_episodes)
        _check(self.validation_seed >= 0, "train.validation_seed", "must be >= 0", self.validation_seed)
        _check(not math.isnan(self.stop_return), "train.stop_return", "must be a number (inf = never)",
               self.stop_return)
        _check(self.seed >= 0, "train.seed", "must be >= 0", self.seed)

    @property
    def eval_interval(self) -> int:
        """Env steps between greedy evaluations during training (0 = none): ``eval_every`` resolved."""
        if self.eval_every >= 0:
            return self.eval_every
        return self.env_steps // 10 if self.env_steps >= AUTO_EVAL_FROM else 0


@dataclass(frozen=True)
class DeployConfig:
    """Where each component runs: Ray actor resources, the router's address, supervision.

    Every component (zenoh router, replay server, learner, env workers) is a Ray actor, each its
    own process (a local run's router excepted: ``router_in``); these fields are its Ray options.
    Custom resources place a component on a node that offers them (``ray start --resources
    '{"laneshift_replay": 1}'``); ``GPU`` in ``learner_resources`` becomes the learner's ``num_gpus``.
    """

    # The router listens on this port on its node. 0: a free port (local mode) or 7447 (cluster).
    router_port: int = 0
    # Where the router runs. "actor": its own Ray actor, placed by router_resources and restarted
    # by Ray. "launcher": a zenoh session in the launcher's own process, local mode only. A local
    # run's Ray processes all die with its launcher, so there an actor adds no supervision worth
    # its process: a Ray worker holding one zenoh session cost about 106 MB of the run's 1.24 GB
    # peak memory (`laneshift bench run`; docs/performance-log.md). "auto": the launcher in local mode, an actor on a cluster.
    router_in: Literal["auto", "actor", "launcher"] = "auto"
    # The address the router listens on and every client connects to. "" = the address Ray
    # registered for the router's node (``ray start --node-ip-address``), 127.0.0.1 in local mode.
    advertise_host: str = ""
    # The endpoint env workers connect to, when not the run's router itself: a relay or proxy in
    # front of it (e.g. a router per node meshed with the run's, or the chaos suite's slow link).
    worker_router: str = ""
    router_cpus: float = 0.0  # Ray num_cpus of the router actor
    replay_cpus: float = 1.0  # Ray num_cpus of each replay server
    learner_cpus: float = 1.0  # Ray num_cpus of the learner
    worker_cpus: float = 1.0  # Ray num_cpus of each env worker
    router_resources: dict[str, float] = field(default_factory=dict)  # Ray custom resources of the router actor
    replay_resources: dict[str, float] = field(default_factory=dict)  # Ray custom resources of each replay server
    learner_resources: dict[str, float] = field(default_factory=dict)  # of the learner (GPU: its num_gpus)
    worker_resources: dict[str, float] = field(default_factory=dict)  # Ray custom resources of each env worker
    # Ray restarts a component that died this many times (the run fails after that).
    max_restarts: int = 5
    start_timeout_s: float = 180.0  # a component that is not serving by then fails the run, named
    # No transition stored for this long while workers run: fail with a message instead of waiting forever.
    stall_timeout_s: float = 300.0
    # k >= 0: the learner's process runs on CPU k alone and every other component process of the
    # run on the node's other CPUs (os.sched_setaffinity), so the learner's update never waits for
    # a core the env workers hold (+25 % env steps/s on 2 cores: `laneshift bench run`, with
    # --set deploy.learner_core=-1 and without; docs/performance-log.md).
    # -1: no pinning. -2 (auto, the default): local mode pins the learner to the machine's last CPU
    # when the launcher may use two or more; a cluster run pins nothing (``resolve_learner_core``).
    learner_core: int = -2

    def __post_init__(self) -> None:
        _check_choices(self, "deploy")
        _check(0 <= self.router_port <= 65535, "deploy.router_port", "must be 0 (default) or a port",
               self.router_port)
        _check(self.worker_router == "" or self.worker_router.startswith(("tcp/", "udp/")), "deploy.worker_router",
               "must be empty or a zenoh endpoint like tcp/10.0.0.5:7447", self.worker_router)
        for name in ("router_cpus", "replay_cpus", "learner_cpus", "worker_cpus"):
            _check(getattr(self, name) >= 0, f"deploy.{name}", "must be >= 0", getattr(self, name))
        for name in ("router_resources", "replay_resources", "learner_resources", "worker_resources"):
            res = getattr(self, name)
            _check(all(isinstance(k, str) and k and isinstance(v, (int, float)) and v >= 0 for k, v in res.items()),
                   f"deploy.{name}", "must map resource names to amounts >= 0", res)
            _check("CPU" not in res, f"deploy.{name}", "must not name CPU (use deploy.*_cpus)", res)
        _check(self.max_restarts >= 0, "deploy.max_restarts", "must be >= 0", self.max_restarts)
        _check(self.start_timeout_s > 0, "deploy.start_timeout_s", "must be > 0", self.start_timeout_s)
        _check(self.stall_timeout_s > 0, "deploy.stall_timeout_s", "must be > 0", self.stall_timeout_s)
        _check(self.learner_core >= -2, "deploy.learner_core", "must be -2 (auto), -1 (off) or a CPU number",
               self.learner_core)


@dataclass(frozen=True)
class RunConfig:
    env: EnvConfig = field(default_factory=EnvConfig)
    actor: ActorConfig = field(default_factory=ActorConfig)
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    learner: LearnerConfig = field(default_factory=LearnerConfig)
    transport: TransportConfig = field(default_factory=TransportConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    deploy: DeployConfig = field(default_factory=DeployConfig)

    def __post_init__(self) -> None:
        largest = self.largest_message_bytes
        if self.transport.max_message_mb and self.transport.max_message_mb * 2**20 < largest:
            raise ConfigError(f"transport.max_message_mb: a sample reply of this run takes up to "
                              f"{largest / 2**20:.1f} MiB, so the limit must be above that, "
                              f"got {self.transport.max_message_mb!r}")
        rows = self.learner.batch_size * max(self.learner.prefetch, self.learner.updates_per_round)
        if self.replay.samples_per_insert and rows > self.replay.spi_tolerance:
            raise ConfigError(f"replay.spi_tolerance: must be >= the rows of one sample request "
                              f"(learner.batch_size x max(prefetch, updates_per_round) = {rows}), or sampling and "
                              f"inserting could block each other forever, got {self.replay.spi_tolerance!r}")
        if self.learner.heads != 1 and not (self.env.is_allroads and self.learner.heads == len(ROADS)):
            raise ConfigError(f"learner.heads: one head per road takes env.scenario=allroads and "
                              f"{len(ROADS)} heads (one per road, picked by the observation's road one-hot), "
                              f"got {self.learner.heads!r} on scenario {self.env.scenario!r}")
        if not self.learner.phase1_td and self.replay.sampler == "prioritized":
            # An imitation-only update has no TD error to give the demo rows as their priority.
            raise ConfigError("learner.phase1_td: false has no TD errors for replay.sampler=prioritized's priorities "
                              "in phase 1; use the uniform sampler, or keep learner.phase1_td true")
        if self.learner.frozen_steps and self.env.observation != "grayscale":
            raise ConfigError(f"learner.frozen_steps: freezes a frame network's layers, so it needs "
                              f"env.observation=grayscale, got {self.learner.frozen_steps!r} on "
                              f"env.observation={self.env.observation!r}")
        if self.train.parallel == "sync" and self.learner.n_step > self.actor.send_every:
            # A sync round needs a batch from every worker; its first n - 1 steps complete no item.
            raise ConfigError(f"learner.n_step: must be <= actor.send_every ({self.actor.send_every}) in sync mode, "
                              f"or a worker's first round would have nothing to send, got {self.learner.n_step!r}")

    @property
    def largest_message_bytes(self) -> int:
        """The run's largest message: a sample reply (two observations a row). Grayscale frames
        are 4 x 100 x 100 bytes; vector observations at most a few hundred floats."""
        obs_bytes = 4 * 100 * 100 if self.env.observation == "grayscale" else 4 * 512
        rows = self.learner.batch_size * max(self.learner.prefetch, self.learner.updates_per_round)
        return rows * (2 * obs_bytes + 64)

    @property
    def max_message_bytes(self) -> int:
        """zenoh's receive limit for every session of this run (``transport.max_message_mb``)."""
        if self.transport.max_message_mb:
            return int(self.transport.max_message_mb * 2**20)
        return max(16 * 2**20, 2 * self.largest_message_bytes)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {f.name: _plain(dataclasses.asdict(getattr(self, f.name))) for f in dataclasses.fields(self)}

    def replace(self, **sections: Any) -> "RunConfig":
        return dataclasses.replace(self, **sections)


def worker_names(n: int) -> list[str]:
    """Env workers' names, used in key expressions, stats and Ray actor names: w0, w1, ..."""
    return [f"w{i}" for i in range(n)]


def worker_budgets(total: int, n: int) -> list[int]:
    """The run's env-step budget split over ``n`` workers (the first ones take the remainder)."""
    return [total // n + (i < total % n) for i in range(n)]


SECTIONS: dict[str, type] = {"env": EnvConfig, "actor": ActorConfig, "replay": ReplayConfig, "learner": LearnerConfig,
            "transport": TransportConfig, "train": TrainConfig, "deploy": DeployConfig}


def _plain(d: Mapping[str, Any]) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else dict(v) if isinstance(v, dict) else v for k, v in d.items()}
