"""The components' settings: one flat, frozen dataclass each for the env, the env workers
(``actor``), the replay server and the learner, each refusing a bad value with a ``ConfigError``
that names the field. How a run is wired (transport, train, deploy) and ``RunConfig``, which
groups every section, are ``.run``'s; building them from files and ``--set`` strings is
``.loading``'s.

Room: the contract (shared by every process). May import: the standard library and ``.checks``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Literal

from .checks import ConfigError, _check, _check_choices, row_window

#: The roads of env.scenario=allroads, in the order of its observation's one-hot (``laneshift.envspec``
#: hands this tuple to the env as ``ALLROADS``).
ROADS: tuple[str, ...] = ("straight", "merge", "curve", "roundabout")

SCENARIO_NAMES = ("straight", "merge", "curve", "roundabout", "allroads", "lka")
#: The safety shield's default figures: the scripted driver's bumper gap [m] and planning deceleration
#: [m/s^2], as the env's GapShield has them (actors/envs/shield.py; tests/test_shield.py holds them equal).
SHIELD_GAP, SHIELD_DECEL = 3.0, 0.9


@dataclass(frozen=True)
class EnvConfig:
    """Which environment every actor runs (the env's own kwargs, flat)."""

    # straight | merge | curve | roundabout | allroads (the four roads, one network) | lka, or a full gymnasium id
    scenario: str = "straight"
    observation: Literal["vector", "grayscale"] = "vector"  # vector (fast, CPU default) | grayscale (paper: 4 x 100 x 100)
    # grayscale only: frames drawn at k times the resolution and each k x k block averaged (anti-aliased:
    # a car's position inside a pixel shows in its edge's grey; 1 = pygame's whole-pixel polygons).
    # Recorded in checkpoints.
    frame_supersample: int = 1
    # grayscale only: policy steps between two stacked frames (1 = the last 4 frames; k: the frames
    # at t, t-k, t-2k, t-3k, so a speed difference moves a car k times as many pixels between them).
    # Recorded in checkpoints.
    frame_interval: int = 1
    # grayscale only: the ego's place across the frame's width, a fraction from its left edge (world x,
    # the straight road's driving direction): 0.5 centres it; highway-env's observations use 0.3 (70 %
    # of the view ahead). Recorded in checkpoints.
    frame_centering: float = 0.5
    # grayscale only: pixels per metre (2: the 100 x 100 frame shows 50 m of road, 25 m ahead of a
    # centred ego; 1: 100 m, cars 5 x 2 px). The paper gives the crop's size, not its scale.
    # Recorded in checkpoints.
    frame_scale: float = 2.0
    reward_preset: int = 5  # Table 1 condition (lane-change scenarios only)
    max_steps: int = 0  # 0 = the scenario's default episode length (allroads: 300 on every road)
    initial_lane: Literal["random", "non-target"] = "random"  # random | non-target
    action_set: Literal["paper", "meta"] = "paper"  # paper (9 actions) | meta (highway-env meta-actions)
    policy_vehicles: int = 0  # other vehicles driven by a copy of the agent's policy
    # Per-lane gap features in the vector observation (False: the earlier 11 + 7 K layout).
    lane_features: bool = True
    # Per lane slot: a car alongside (1/0) and the nearest bumper gap at 10 m scale (needs lane_features)
    alongside_features: bool = False
    # Per side (left, right): that lane is there (1/0) and the distance along it to the middle of its
    # nearest gap long enough to merge into, at 50 m scale (the scripted driver's alignment target;
    # needs lane_features). Recorded in checkpoints.
    gap_features: bool = False
    # A safety shield before each step (actors/envs/shield.py): an action a gap rule on what the lane
    # block sees calls unsafe is replaced by a safe one (paper action set). Recorded in checkpoints.
    shield: bool = False
    # The shield's bumper gap kept [m] (with env.shield; the scripted driver's by default). Recorded in checkpoints.
    shield_gap: float = SHIELD_GAP
    # The speed change the shield plans with [m/s^2] (with env.shield; the scripted driver's by default; at
    # most the paper actions' own 1 m/s^2). Recorded in checkpoints.
    shield_decel: float = SHIELD_DECEL
    # allroads only: "" = each episode's road is drawn from its reset seed (seed % 4: straight, merge,
    # curve, roundabout); a road's name = every episode on that road (to test one road)
    road: str = ""

    def __post_init__(self) -> None:
        _check_choices(self, "env")
        _check(self.scenario in SCENARIO_NAMES or "/" in self.scenario, "env.scenario",
               f"must be one of {SCENARIO_NAMES} or a gymnasium id", self.scenario)
        _check(1 <= self.reward_preset <= 5, "env.reward_preset", "must be 1..5 (Table 1)", self.reward_preset)
        _check(self.max_steps >= 0, "env.max_steps", "must be >= 0", self.max_steps)
        _check(self.policy_vehicles >= 0, "env.policy_vehicles", "must be >= 0", self.policy_vehicles)
        _check(self.road in ("", *ROADS), "env.road",
               "must be empty (each episode draws its road) or straight, merge, curve or roundabout", self.road)
        _check(not self.road or self.is_allroads, "env.road", "pins the road of env.scenario=allroads only "
               f"(env.scenario is {self.scenario!r})", self.road)
        _check(self.lane_features or not self.alongside_features, "env.alongside_features",
               "extends the lane features: it needs env.lane_features=true", self.alongside_features)
        _check(self.lane_features or not self.gap_features, "env.gap_features",
               "extends the lane features: it needs env.lane_features=true", self.gap_features)
        _check(not (self.shield and (self.is_lka or self.action_set != "paper")), "env.shield",
               "guards the lane changes of the paper action set (not lka, not action_set=meta)", self.shield)
        _check(isinstance(self.frame_supersample, int) and not isinstance(self.frame_supersample, bool)
               and 1 <= self.frame_supersample <= 8, "env.frame_supersample", "must be an integer 1..8",
               self.frame_supersample)
        _check(self.frame_supersample == 1 or self.observation == "grayscale", "env.frame_supersample",
               "draws the grayscale frames: it needs env.observation=grayscale", self.frame_supersample)
        _check(isinstance(self.frame_interval, int) and not isinstance(self.frame_interval, bool)
               and 1 <= self.frame_interval <= 30, "env.frame_interval", "must be an integer 1..30",
               self.frame_interval)
        _check(self.frame_interval == 1 or self.observation == "grayscale", "env.frame_interval",
               "spaces the stacked grayscale frames: it needs env.observation=grayscale", self.frame_interval)
        _check(0.0 < self.frame_centering < 1.0, "env.frame_centering", "must be in (0, 1)", self.frame_centering)
        _check(self.frame_centering == 0.5 or self.observation == "grayscale", "env.frame_centering",
               "places the ego in the grayscale frames: it needs env.observation=grayscale", self.frame_centering)
        _check(0.5 <= self.frame_scale <= 8.0, "env.frame_scale", "must be in [0.5, 8] pixels per metre",
               self.frame_scale)
        _check(self.frame_scale == 2.0 or self.observation == "grayscale", "env.frame_scale",
               "scales the grayscale frames: it needs env.observation=grayscale", self.frame_scale)
        _check(self.shield_gap > 0, "env.shield_gap", "must be > 0 m", self.shield_gap)
        _check(0 < self.shield_decel <= 1.0, "env.shield_decel",
               "must be in (0, 1] m/s^2 (the paper actions change the speed by at most 1 m/s^2)", self.shield_decel)
        for name, default in (("shield_gap", SHIELD_GAP), ("shield_decel", SHIELD_DECEL)):
            _check(self.shield or getattr(self, name) == default, f"env.{name}",
                   "sets a figure of the safety shield: it needs env.shield=true", getattr(self, name))
        _check(not (self.is_allroads and self.observation == "grayscale"), "env.observation",
               "allroads needs the vector observation (the road's one-hot is appended to it; a frame has "
               "no place for it)", self.observation)

    @property
    def is_allroads(self) -> bool:
        return self.scenario in ("allroads", "laneshift/AllRoadsLaneChange-v0")

    @property
    def is_lka(self) -> bool:
        return self.scenario in ("lka", "laneshift/LaneKeepingAssist-v0")

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for ``make_env`` (LKA takes none of the lane-change options)."""
        if self.is_lka:
            return {"max_steps": self.max_steps} if self.max_steps else {}
        kw: dict[str, Any] = {"observation": self.observation, "reward_preset": self.reward_preset,
                              "initial_lane": self.initial_lane, "action_set": self.action_set}
        if self.max_steps:
            kw["max_steps"] = self.max_steps
        if self.policy_vehicles:
            kw["policy_vehicles"] = self.policy_vehicles
        if not self.lane_features:
            kw["lane_features"] = False
        if self.alongside_features:
            kw["alongside_features"] = True
        if self.gap_features:
            kw["gap_features"] = True
        if self.shield:
            kw["shield"] = True
        if self.shield_gap != SHIELD_GAP:
            kw["shield_gap"] = self.shield_gap
        if self.shield_decel != SHIELD_DECEL:
            kw["shield_decel"] = self.shield_decel
        if self.frame_supersample != 1:
            kw["frame_supersample"] = self.frame_supersample
        if self.frame_interval != 1:
            kw["frame_interval"] = self.frame_interval
        if self.frame_centering != 0.5:
            kw["frame_centering"] = self.frame_centering
        if self.frame_scale != 2.0:
            kw["frame_scale"] = self.frame_scale
        if self.road:
            kw["road"] = self.road
        return kw


@dataclass(frozen=True)
class ActorConfig:
    """Env workers (Ray actors): how many, how they explore, how often they send."""

    workers: int = 2  # env workers, one Ray actor (process) each
    envs_per_worker: int = 1  # envs each worker steps in turn, acting for all of them in one forward pass
    send_every: int = 32  # publish a transitions batch every K env steps (MATLAB: "every N steps")
    exploration: Literal["linear", "exponential", "apex"] = "linear"  # linear (paper) | exponential (MATLAB) | apex (per-actor fixed epsilons)
    epsilon_start: float = 1.0  # exploration at a worker's first step
    epsilon_final: float = 0.1  # paper condition 5: 1.0 -> 0.1
    epsilon_decay_steps: int = 0  # linear: a worker's env steps from start to final; 0 = half its budget
    epsilon_decay_rate: float = 1e-4  # exponential: eps *= (1 - rate) per step (MATLAB EpsilonDecay)
    # Rehearsal phase 2 is "a new training run" (paper): exploration restarts at epsilon_start.
    # A value >= 0 starts phase 2 there instead, to keep more of what phase 1 learned.
    phase2_epsilon_start: float = -1.0
    apex_epsilon: float = 0.4  # apex: eps_i = apex_epsilon ** (1 + apex_alpha * i / (N - 1))
    apex_alpha: float = 7.0  # apex: how fast the per-actor epsilons fall from the first actor to the last
    # Temporally-extended epsilon-greedy (ez-greedy, Dabney et al. 2021): an exploratory action is held for n
    # steps, n drawn from a zeta distribution with this exponent (their mu = 2) cut at hold_max. 0: plain
    # epsilon-greedy, one step each (the paper's).
    hold_mu: float = 0.0
    hold_max: int = 100  # the longest hold [env steps] (with hold_mu > 0)
    torch_threads: int = 1  # torch threads in each worker process (its acting forward pass)
    seed: int = 0  # worker i seeds its env and exploration from seed + i

    def __post_init__(self) -> None:
        _check_choices(self, "actor")
        _check(self.workers >= 1, "actor.workers", "must be >= 1", self.workers)
        _check(self.envs_per_worker >= 1, "actor.envs_per_worker", "must be >= 1", self.envs_per_worker)
        _check(self.send_every >= 1, "actor.send_every", "must be >= 1", self.send_every)
        _check(self.phase2_epsilon_start == -1.0 or 0.0 <= self.phase2_epsilon_start <= 1.0,
               "actor.phase2_epsilon_start", "must be -1 (restart at epsilon_start) or in [0, 1]",
               self.phase2_epsilon_start)
        for name in ("epsilon_start", "epsilon_final", "apex_epsilon"):
            v = getattr(self, name)
            _check(0.0 <= v <= 1.0, f"actor.{name}", "must be in [0, 1]", v)
        _check(self.epsilon_decay_steps >= 0, "actor.epsilon_decay_steps", "must be >= 0 (0 = half the budget)",
               self.epsilon_decay_steps)
        _check(0.0 <= self.epsilon_decay_rate < 1.0, "actor.epsilon_decay_rate", "must be in [0, 1)",
               self.epsilon_decay_rate)
        _check(self.torch_threads >= 1, "actor.torch_threads", "must be >= 1", self.torch_threads)
        _check(self.apex_alpha >= 0, "actor.apex_alpha", "must be >= 0", self.apex_alpha)  # also refuses NaN
        _check(self.hold_mu == 0.0 or self.hold_mu > 1.0, "actor.hold_mu",
               "must be 0 (one-step exploration) or > 1 (a zeta distribution's exponent)", self.hold_mu)
        _check(self.hold_max >= 1, "actor.hold_max", "must be >= 1", self.hold_max)
        _check(self.seed >= 0, "actor.seed", "must be >= 0", self.seed)


DEMO_MODES: tuple[str, ...] = ("none", "retention", "rehearsal", "dqfd")  # ReplayConfig.demo_mode's choices


@dataclass(frozen=True)
class ReplayConfig:
    """The replay server: tables, demo mode and rate limiting."""

    capacity: int = 100_000  # total items, demo region included (retention)
    # none | retention | rehearsal (the paper's three) | dqfd (beyond the paper, Hester et al. 2018:
    # rehearsal's demo-only phase 1, then retention's fixed demo region in phase 2)
    demo_mode: Literal["none", "retention", "rehearsal", "dqfd"] = "none"
    demo_ratio: float = 0.1  # retention/dqfd: share of the buffer that is demos, never evicted
    # Demo shards (Minari datasets) loaded at start. Empty with a demo mode: `train` generates the
    # scripted demonstrator's shard; a bare replay server refuses to start.
    demo_paths: tuple[str, ...] = ()
    min_size: int = 1_000  # online items needed before sampling (not in rehearsal phase 1)
    # Reverb-style SampleToInsertRatio: sampled rows per inserted item (0 = no ratio). With batch
    # 256, 32 means one update per 8 env steps; actors wait when the learner falls behind.
    samples_per_insert: float = 32.0
    spi_tolerance: float = 8192.0  # rows of slack either side of the ratio (>= one sample request)
    sampler: Literal["uniform", "prioritized"] = "uniform"  # uniform | prioritized (sum tree, Schaul et al. 2016)
    priority_alpha: float = 0.6  # P(i) ~ p_i ** alpha
    priority_beta: float = 0.4  # importance-sampling exponent (1 = full correction)
    priority_eps: float = 1e-3  # added to |TD error| so no item starves
    demo_priority_bonus: float = 1.0  # DQfD's epsilon_d: extra priority for demo items
    # Online-table checkpoints in <run dir>/replay_checkpoint, written without blocking inserts or
    # samples; they bound the write-ahead log (wal) and are what survives host loss. With wal off a
    # kill -9 loses about one interval of agent experience (counted). 0 = only at shutdown.
    checkpoint_every_s: float = 60.0
    # Write-ahead log in <run dir>/replay_checkpoint.wal: each accepted batch is written there
    # before it is stored, and replayed after the checkpoint at a restart, so a kill -9 of the
    # server loses only batches not yet received (docs/RELIABILITY.md). write: each batch reaches
    # the OS (survives the process, not the host); fsync: also on disk (host loss; slower); off:
    # none (a kill -9 loses what arrived since the last checkpoint, counted).
    wal: Literal["off", "write", "fsync"] = "write"
    # The log's bound: past this many MiB since the last checkpoint a checkpoint starts at once
    # (also with checkpoint_every_s 0), after which the log is cut back. 0 = no bound.
    wal_max_mb: float = 1024.0
    restore: bool = True  # restore the online table from the run dir's checkpoint (and log) at start
    http_port: int = -1  # HTTP inspection API: -1 off, 0 a free port, else that port
    http_host: str = "127.0.0.1"  # bind elsewhere only on purpose: the API has no authentication
    # Per-actor state is bounded (4,096 actors, a place of them kept for each of the run's env
    # workers); any other new actor beyond that evicts the other actor idle longest, if it has been
    # idle this long, else it is refused (counted as too_many_actors).
    actor_idle_evict_s: float = 600.0
    # Stacked image observations are held once per frame (replay_server/frames.py): a ring of this
    # many frames per item of capacity. About 1 new frame an item in steady state, and an item lives
    # for 3/4 of the ring's turn, so 2 holds the whole table; when the ring runs out first, the
    # oldest items go early (stats: online.frames.evicted_for_frames).
    frames_per_item: float = 2.0
    # Replay-server shards, to scale the replay out: each holds capacity / shards items (and its own
    # demo region in retention), each env worker sends to one (wire.shard_of: a stable function of
    # its name) and the learner samples across them in proportion to their sizes (learner/shards.py).
    shards: int = 1
    seed: int = 0  # the sampler's random generator (shard i: seed + i)

    def __post_init__(self) -> None:
        _check_choices(self, "replay")
        for name in ("priority_alpha", "priority_beta"):
            _check(0.0 <= getattr(self, name) <= 1.0, f"replay.{name}", "must be in [0, 1]", getattr(self, name))
        _check(self.priority_eps > 0, "replay.priority_eps", "must be > 0", self.priority_eps)
        _check(self.demo_priority_bonus >= 0, "replay.demo_priority_bonus", "must be >= 0", self.demo_priority_bonus)
        _check(-1 <= self.http_port <= 65535, "replay.http_port", "must be -1 (off), 0 (any free port) or a port",
               self.http_port)
        _check(self.checkpoint_every_s >= 0, "replay.checkpoint_every_s", "must be >= 0", self.checkpoint_every_s)
        _check(self.wal_max_mb >= 0, "replay.wal_max_mb", "must be >= 0 (0 = no bound)", self.wal_max_mb)
        _check(self.actor_idle_evict_s >= 0, "replay.actor_idle_evict_s", "must be >= 0", self.actor_idle_evict_s)
        _check(self.capacity >= 2, "replay.capacity", "must be >= 2", self.capacity)
        _check(0.0 < self.demo_ratio < 1.0, "replay.demo_ratio", "must be in (0, 1)", self.demo_ratio)
        _check(self.min_size >= 1, "replay.min_size", "must be >= 1", self.min_size)
        _check(self.min_size <= self.capacity, "replay.min_size", f"must be <= replay.capacity ({self.capacity}) "
               "or sampling could never start", self.min_size)
        _check(self.samples_per_insert >= 0, "replay.samples_per_insert", "must be >= 0", self.samples_per_insert)
        _check(self.spi_tolerance >= 0, "replay.spi_tolerance", "must be >= 0", self.spi_tolerance)
        _check(self.seed >= 0, "replay.seed", "must be >= 0", self.seed)
        _check(self.frames_per_item >= 1.0, "replay.frames_per_item", "must be >= 1", self.frames_per_item)
        _check(1 <= self.shards <= 64, "replay.shards", "must be in [1, 64]", self.shards)
        _check(self.capacity // self.shards >= 2 and self.min_size >= self.shards, "replay.shards",
               f"each shard needs >= 2 items of replay.capacity ({self.capacity}) and >= 1 of replay.min_size "
               f"({self.min_size})", self.shards)

    def shard(self, index: int) -> "ReplayConfig":
        """Shard ``index``'s own table config (itself when there is one shard): its share of ``capacity``
        and of ``min_size`` (the first shards take the remainder), its own seed (so each shard
        draws its own retention demo subset), and ``http_port`` + index when a port is fixed."""
        n = self.shards
        if n == 1:
            return self
        if not 0 <= index < n:
            raise ConfigError(f"replay shard {index} of {n}")

        def share(total: int) -> int:
            return total // n + (1 if index < total % n else 0)

        # ``shards=1``: the result describes one replay server's own table.
        return dataclasses.replace(self, capacity=share(self.capacity), min_size=max(1, share(self.min_size)),
                                   seed=self.seed + index, shards=1,
                                   http_port=self.http_port + index if self.http_port > 0 else self.http_port)

    @property
    def retains_demos(self) -> bool:
        """Demos are a fixed region of the buffer while the agent learns online."""
        return self.demo_mode in ("retention", "dqfd")

    @property
    def pretrains(self) -> bool:
        """A phase 1 of demo-only updates (agent transitions not stored) comes first."""
        return self.demo_mode in ("rehearsal", "dqfd")


@dataclass(frozen=True)
class LearnerConfig:
    """Double DQN hyperparameters (all of them, CleanRL style) and the learner's cadence."""

    lr: float = 5e-4  # Adam's step size
    # The learning rate at the end of the env-step budget: it falls linearly from ``lr`` as the run's
    # env steps go from 0 to train.env_steps (pre-training keeps ``lr``). 0 = constant ``lr``.
    # A decaying step size lets the last network settle instead of being one draw of the TD noise.
    lr_final: float = 0.0
    # Weight averaging: the network the run publishes, evaluates and checkpoints is an exponential
    # moving average of the online network's weights, updated after every update with this decay
    # (torch.optim.swa_utils; 0.999 averages over about the last 1,000 updates). 0 = off (online).
    ema_decay: float = 0.0
    gamma: float = 0.99  # discount per env step
    # n-step returns (DQfD, Rainbow): actors and the demo loader sum n rewards per item, the target
    # bootstraps with gamma^n. 1 = the paper's one-step Double DQN.
    n_step: int = 1
    batch_size: int = 256  # MATLAB minibatch 256
    hidden: tuple[int, ...] = (256, 256)  # MLP for vector observations (CNN for grayscale)
    # The CNN for grayscale frames: nature (Mnih et al. 2015) or small (laneshift.qnet SmallCNN,
    # about 3x the updates/s on 2 CPU cores; what the pixel Table 2 runs use).
    cnn: Literal["nature", "small"] = "nature"
    # The rows of each frame the CNN looks at, "first:end" (end excluded; "" = all): the observation
    # stays whole on the wire and in the replay, and the network's first step keeps these rows. On
    # the straight road at 2 px/m the road is a band around the centred ego and the rest of the
    # 100 x 100 frame is off-road black (rows 26-70 held anything else in 12 episodes of random
    # actions): "22:78" holds the band under learner.augment's 4-pixel shift, at about half the
    # whole frame's update cost. Recorded in checkpoints (in the network's name, learner.network_cnn).
    cnn_rows: str = ""
    # Image augmentation of grayscale batches (DrQ, Kostrikov et al. 2021): in every update each
    # row's frames of obs and of next_obs are shifted by up to ``augment_pad`` pixels each way (edge
    # pixels repeated), a fresh shift per row. none = off; vector observations are never augmented.
    augment: Literal["none", "shift"] = "none"
    # The learner's convolutions in bfloat16 (autocast; the parameters, the layers after the
    # convolutions and the loss stay float32): 1.57x the SmallCNN updates/s at batch 32 on the
    # dev machine's AMD EPYC, which has avx512_bf16 (`laneshift bench learner --cases small-b32,small-b32-bf16`).
    # A CPU without bfloat16 instructions emulates them, far slower than fp32 (an AMD EPYC without
    # avx512_bf16: 2.0 against 23.4 updates/s), and the learner says so in one line at its start
    # (`laneshift bench learner` names the CPU's bfloat16 support in its header). Acting stays float32.
    cnn_precision: Literal["fp32", "bf16"] = "fp32"
    # The same for an MLP's hidden layers (vector observations; the head and the loss stay float32).
    # On the dev machine's Intel Xeon (AMX units multiply bfloat16 matrices) the update at batch 256
    # ran 1.77x as fast with 512 x 512 units (178 against 101 a second) and 1.20x with 256 x 256
    # (`laneshift bench learner --cases mlp-b256,mlp-b256-bf16,mlp512-b256,mlp512-b256-bf16`);
    # without bfloat16 instructions it is slower than fp32 (the learner's start says so in one line).
    mlp_precision: Literal["fp32", "bf16"] = "fp32"
    augment_pad: int = 4  # the largest shift of learner.augment=shift, in pixels
    target_update_period: int = 500  # updates between hard target-network syncs
    huber_delta: float = 1.0  # the TD loss is quadratic within this distance, linear beyond
    # The value the TD target takes after an episode's terminal step (a crash or leaving the road)
    # instead of 0 (the paper's). Condition 5 pays -5 for a crash and -1 a step for driving on in a
    # non-target lane, so with gamma 0.99 a crash is worth more than waiting about five steps for a
    # gap, and Q-learning learns to prefer it. A value at or below the worst way of staying alive
    # (-1 / (1 - gamma) = -100 for driving on in a non-target lane) makes a crash never pay; the
    # env's reward and the evaluation are unchanged.
    terminal_value: float = 0.0
    grad_clip: float = 10.0  # global-norm gradient clipping (MATLAB threshold: 1)
    weight_decay: float = 0.0  # L2 regularisation (MATLAB: 1e-4)
    double: bool = True  # Double DQN target; False = vanilla DQN (for comparison)
    # DQfD (Hester et al. 2018) large-margin loss on demo rows: lambda * (max_a [Q(s,a) + m 1{a != a_E}]
    # - Q(s,a_E)), pushing the demonstrator's action above the others by a margin. 0 = off.
    margin_loss_weight: float = 0.0
    margin: float = 0.8  # DQfD's m: how far the demonstrator's action must stand above the others
    # Supervised imitation on demo rows: cross-entropy of softmax(Q(s, .)) against the demo action. 0 = off.
    bc_loss_weight: float = 0.0
    # The imitation losses' weight (margin_loss_weight and bc_loss_weight together) at the end of
    # their fall, as a fraction of their own: it falls linearly from 1 as the run's env steps go from
    # 0 to imitation_fade_steps (0 = train.env_steps) and stays there; pre-training keeps the full
    # weight. 1 = constant (DQfD's). Below 1 the demonstrator's actions pull less as the agent's own
    # experience grows, so the TD loss alone decides where the demonstrator was wrong: a way past a
    # teacher that the imitation holds the network level with.
    imitation_final: float = 1.0
    imitation_fade_steps: int = 0  # env steps over which learner.imitation_final is reached (0 = the budget)
    dueling: bool = False  # dueling head (Wang et al. 2016): Q = V + A - mean A
    # One Q head per road on a shared trunk (env.scenario=allroads only: 4, one per road, picked by the
    # road's one-hot that ends its observation). 1 = one head for every road.
    heads: int = 1
    publish_every: int = 50  # updates between weight broadcasts (async)
    updates_per_round: int = 8  # sync: updates per round of worker batches
    phase1_updates: int = 2_000  # rehearsal: demo-only updates before phase 2
    # Whether phase 1 (the pre-training on the demo shard) trains the TD loss beside the imitation
    # losses (DQfD's pre-training). False: the imitation losses alone (margin_loss_weight and
    # bc_loss_weight; one of them must be on), an update without the passes over the next
    # observations and the target network; phase 2 then learns the values with the imitation kept.
    # On frames a copy trained by cross-entropy alone drove far better than DQfD's pre-training
    # (docs/RESULTS.md, pixels).
    phase1_td: bool = True
    # The first N env steps of phase 2 keep some of a frame network's layers at their pre-trained
    # (phase-1) weights and train the rest (learner.frozen_layers): linear probing, then fine-tuning
    # (Kumar et al. 2022, LP-FT: an output layer that does not yet fit the new loss distorts the
    # pre-trained features when everything is tuned at once). On frames, phase 2's TD loss took the
    # mean Q-value from the imitation's -11 to 121 in 10,000 updates, at 30-40 times phase 1's gradient
    # norm, and the pre-trained copy's driving went with it; after that pre-training, all-but-output
    # for the whole run ended 15.5 and 7 points of validation achievement above the best recipe that
    # trained every layer (docs/RESULTS.md, pixels, probes 14, 17 and 18). 0 = nothing frozen;
    # train.env_steps or more = the whole run. Frame observations (env.observation=grayscale) only.
    frozen_steps: int = 0
    # What learner.frozen_steps freezes: all-but-output (every layer but the Q output layer, the dueling
    # head's value and advantage layers: linear probing) | convolutions (the CNN's layers only).
    frozen_layers: Literal["all-but-output", "convolutions"] = "all-but-output"
    checkpoint_every: int = 5_000  # updates between checkpoints in the run dir
    # Full training state (online + target nets, optimizer, update count, weights version) written
    # at least this often, so a restarted learner loses at most this much work. 0 = only at stop.
    checkpoint_every_s: float = 30.0
    # Seconds between the learner's status reports: metrics.jsonl, TensorBoard's learner/* points,
    # the launcher's progress line and /metrics (the fault suite logs every 0.1 s to strike mid-run).
    log_every_s: float = 1.0
    device: Literal["auto", "cpu", "cuda"] = "auto"  # auto (cuda when torch sees a GPU) | cpu | cuda
    # Also keep each periodic checkpoint as checkpoints/u<updates>.safetensors (learning curves of
    # greedy scores: `laneshift experiment checkpoints`); off: only latest/final are kept.
    keep_checkpoints: bool = False
    # Batches per sample request (one round trip, several updates); fewer where the reply would pass
    # 30 MB (pixel rows at batch 128: 3), the size above which glibc maps every buffer anew.
    prefetch: int = 4
    torch_threads: int = 1  # torch threads for the learner's updates
    # Phase 1 (dqfd and rehearsal pre-training on the demo shard) runs while every actor waits: the
    # CPU learner then lifts its pin (deploy.learner_core) and uses this many torch threads; 0 = one
    # per CPU it may use or one, whichever it times faster (again every 30 s: a process busy beside
    # it makes one per CPU several times slower); 1 = as in phase 2 (learner/cpus.py).
    phase1_threads: int = 0
    # The learner's Prometheus /metrics: -1 off, 0 a free port (local runs turn it on), else that port.
    metrics_port: int = -1
    metrics_host: str = "127.0.0.1"  # bind elsewhere only on purpose: no authentication
    seed: int = 0  # network initialisation and the learner's own random draws

    @property
    def network_cnn(self) -> str:
        """The CNN as ``build_q_network`` and a checkpoint name it: ``cnn``, with ``[FIRST:END]`` when
        it looks at a window of rows (``cnn_rows``)."""
        return f"{self.cnn}[{self.cnn_rows.replace(' ', '')}]" if self.cnn_rows else self.cnn

    def __post_init__(self) -> None:
        _check_choices(self, "learner")
        _check(self.lr > 0, "learner.lr", "must be > 0", self.lr)
        _check(0.0 <= self.lr_final <= self.lr, "learner.lr_final", "must be in [0, learner.lr] (0 = constant lr)",
               self.lr_final)
        _check(0.0 <= self.ema_decay < 1.0, "learner.ema_decay", "must be in [0, 1) (0 = off)", self.ema_decay)
        _check(0.0 <= self.gamma <= 1.0, "learner.gamma", "must be in [0, 1]", self.gamma)
        _check(not isinstance(self.n_step, bool) and isinstance(self.n_step, int) and 1 <= self.n_step <= 255,
               "learner.n_step", "must be an int in [1, 255]", self.n_step)
        _check(1 <= self.batch_size <= 8192, "learner.batch_size", "must be 1..8192", self.batch_size)
        _check(len(self.hidden) >= 1 and all(h >= 1 for h in self.hidden), "learner.hidden",
               "must be a non-empty list of positive sizes", self.hidden)
        for name in ("target_update_period", "publish_every", "updates_per_round", "phase1_updates",
                     "checkpoint_every", "prefetch", "torch_threads"):
            _check(getattr(self, name) >= 1, f"learner.{name}", "must be >= 1", getattr(self, name))
        _check(not isinstance(self.heads, bool) and isinstance(self.heads, int) and self.heads >= 1, "learner.heads",
               "must be an int >= 1", self.heads)
        _check(not isinstance(self.phase1_threads, bool) and isinstance(self.phase1_threads, int)
               and self.phase1_threads >= 0, "learner.phase1_threads", "must be an int >= 0 (0 = one per CPU)",
               self.phase1_threads)
        _check(self.prefetch <= 64, "learner.prefetch", "must be <= 64", self.prefetch)
        _check(1 <= self.augment_pad <= 32, "learner.augment_pad", "must be 1..32", self.augment_pad)
        _check(not self.cnn_rows or row_window(self.cnn_rows) is not None, "learner.cnn_rows",
               "must be FIRST:END rows, 0 <= FIRST < END (e.g. 26:74), or empty for the whole frame",
               self.cnn_rows)
        _check(self.huber_delta > 0, "learner.huber_delta", "must be > 0", self.huber_delta)
        _check(math.isfinite(self.terminal_value), "learner.terminal_value", "must be a finite number", self.terminal_value)
        _check(self.grad_clip > 0, "learner.grad_clip", "must be > 0", self.grad_clip)
        _check(self.weight_decay >= 0, "learner.weight_decay", "must be >= 0", self.weight_decay)
        _check(self.margin_loss_weight >= 0, "learner.margin_loss_weight", "must be >= 0", self.margin_loss_weight)
        _check(self.margin >= 0, "learner.margin", "must be >= 0", self.margin)
        _check(self.bc_loss_weight >= 0, "learner.bc_loss_weight", "must be >= 0", self.bc_loss_weight)
        _check(0.0 <= self.imitation_final <= 1.0, "learner.imitation_final", "must be in [0, 1] (1 = constant)",
               self.imitation_final)
        _check(not isinstance(self.imitation_fade_steps, bool) and isinstance(self.imitation_fade_steps, int)
               and self.imitation_fade_steps >= 0, "learner.imitation_fade_steps", "must be an int >= 0 (0 = the budget)",
               self.imitation_fade_steps)
        _check(isinstance(self.phase1_td, bool), "learner.phase1_td", "must be true or false", self.phase1_td)
        _check(self.phase1_td or self.margin_loss_weight > 0 or self.bc_loss_weight > 0, "learner.phase1_td",
               "false leaves phase 1 no loss unless learner.bc_loss_weight or learner.margin_loss_weight is > 0",
               self.phase1_td)
        _check(not isinstance(self.frozen_steps, bool) and isinstance(self.frozen_steps, int)
               and self.frozen_steps >= 0, "learner.frozen_steps", "must be an int >= 0 (0 = nothing frozen)",
               self.frozen_steps)
        _check(self.seed >= 0, "learner.seed", "must be >= 0", self.seed)
        _check(self.checkpoint_every_s >= 0, "learner.checkpoint_every_s", "must be >= 0", self.checkpoint_every_s)
        _check(self.log_every_s > 0, "learner.log_every_s", "must be > 0", self.log_every_s)
        _check(-1 <= self.metrics_port <= 65535, "learner.metrics_port", "must be -1 (off), 0 (any free port) or a port",
               self.metrics_port)
