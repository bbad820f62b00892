"""The paper's lane-change environments (figure 3 (a)-(d)) on highway-env's road and vehicle models.

One class, :class:`LaneChangeEnv`, parameterised by a scenario layout (scenarios.py); the four
registered ids are its subclasses (``road_env``).  Its bases hold the lane queries (lanes.py), how
an action drives a vehicle (driving.py) and the policy vehicles (policy_vehicles.py); this module
validates the options and runs reset and step.  Per step (``policy_frequency`` Hz, default 10 Hz):

1. the ego action is decoded - paper action (dv, kappa) or a highway-env meta action;
2. policy vehicles (copies of the agent) get their own vector observations and act through the
   function given to :meth:`LaneChangeEnv.set_npc_policy` (without one they keep their lane at
   constant speed);
3. ``simulation_frequency / policy_frequency`` sub-steps: highway-env kinematic bicycle for the
   ego and policy vehicles, exact lane following for the constant-speed traffic, and collision /
   off-road checks of the ego and policy vehicles against everything;
4. reward (Table 1 preset, rewards.py), observation, info.

The episode terminates when the ego vehicle collides or leaves the road, and is truncated after
``max_steps`` steps.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from highway_env.road.road import Road
from highway_env.vehicle.kinematics import Vehicle

from . import scenarios
from .actions import META_ACTIONS, paper_actions
from .control import lane_errors
from .driving import Driving
from .lanes import LaneQueries
from .observations import OBS_LIMIT, vector_observation, vector_size
from .policy_vehicles import NpcPolicy, PolicyVehicles
from .rendering import TopDownRenderer
from .shield import GapShield, ShieldView
from .rewards import DEFAULT_REWARD_PRESET, REWARD_TERM_NAMES, compute_reward, get_preset, motion_flags
from .traffic import AgentVehicle, Traffic, collisions, locate

#: Default meta-action speed grid [m/s] (highway-env's default 20-30 m/s is faster than this traffic).
META_TARGET_SPEEDS = (6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0)


def _int_arg(name: str, value: Any, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an int, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        raise ValueError(f"{name} must be in [{lo}, {hi if hi is not None else 'inf'}], got {value!r}")
    return int(value)


def _float_arg(name: str, value: Any, lo: float, hi: float = math.inf, lo_open: bool = False,
               hi_open: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        interval = f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
        raise ValueError(f"{name} must be in {interval}, got {value!r}")
    return v


class LaneChangeEnv(LaneQueries, Driving, PolicyVehicles, gym.Env):
    """Lane change towards a target lane among constant-speed (and policy-driven) traffic.

    All options are flat constructor keyword arguments (see docs/environments.md for the table).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    SCENARIO = "straight"
    DEFAULT_MAX_STEPS = 300
    DEFAULT_VEHICLES = 30

    def __init__(
        self,
        observation: str = "vector",
        reward_preset: int = DEFAULT_REWARD_PRESET,
        max_steps: int | None = None,
        initial_lane: str | int = "random",
        target_lane: int | str | None = None,
        action_set: str = "paper",
        vehicles_count: int | None = None,
        lanes_count: int | None = None,
        lane_speeds: Sequence[float] | None = None,
        policy_vehicles: int = 0,
        observation_shape: Sequence[int] = (100, 100),
        stack_size: int = 4,
        frame_scale: float = 2.0,
        frame_supersample: int = 1,
        frame_interval: int = 1,
        frame_centering: float = 0.5,
        vehicles_observed: int = 8,
        lane_features: bool = True,
        alongside_features: bool = False,
        gap_features: bool = False,
        shield: bool = False,
        shield_gap: float = GapShield.buffer,
        shield_decel: float = GapShield.decel,
        speed_step: float = 0.1,
        curvature_step: float = 0.01,
        ego_speed_spread: float = 2.0,
        min_gap: float = 12.0,
        ego_clearance: float = 20.0,
        policy_frequency: int = 10,
        simulation_frequency: int = 10,
        meta_target_speeds: Sequence[float] = META_TARGET_SPEEDS,
        render_mode: str | None = None,
    ) -> None:
        super().__init__()
        # ---- validation (ValueError naming the argument) ------------------------------------
        if observation not in ("vector", "grayscale"):
            raise ValueError(f"observation must be 'vector' or 'grayscale', got {observation!r}")
        self.preset = get_preset(reward_preset)
        if action_set not in ("paper", "meta"):
            raise ValueError(f"action_set must be 'paper' or 'meta', got {action_set!r}")
        lo, hi, default_lanes = scenarios.LANES_RANGE[self.SCENARIO]
        n_lanes = default_lanes if lanes_count is None else _int_arg("lanes_count", lanes_count, lo, hi)
        self.layout = scenarios.BUILDERS[self.SCENARIO](n_lanes)
        n_all = self.layout.lanes_count
        self.max_steps = self.DEFAULT_MAX_STEPS if max_steps is None else _int_arg("max_steps", max_steps, 1)
        if initial_lane not in ("random", "non-target") and not (
            isinstance(initial_lane, (int, np.integer)) and not isinstance(initial_lane, bool)
            and int(initial_lane) in self.layout.spawn_lanes
        ):
            raise ValueError(
                f"initial_lane must be 'random', 'non-target' or a lane in {self.layout.spawn_lanes}, got {initial_lane!r}"
            )
        self.initial_lane = initial_lane
        if target_lane is None:
            target_lane = self.layout.default_target
        if target_lane != "random":
            target_lane = _int_arg("target_lane", target_lane, 0, n_all - 1)
        self.target_lane_option = target_lane
        self.vehicles_count = _int_arg(
            "vehicles_count", self.DEFAULT_VEHICLES if vehicles_count is None else vehicles_count, 0
        )
        speeds = scenarios.default_lane_speeds(len(self.layout.npc_lanes)) if lane_speeds is None else list(lane_speeds)
        if len(speeds) != len(self.layout.npc_lanes):
            raise ValueError(f"lane_speeds needs {len(self.layout.npc_lanes)} values (one per traffic lane), got {speeds!r}")
        for v in speeds:
            _float_arg("lane_speeds", v, 0.0, AgentVehicle.MAX_SPEED)
        self.lane_speeds = np.zeros(n_all)
        self.lane_speeds[self.layout.npc_lanes] = speeds
        self.policy_vehicles = _int_arg("policy_vehicles", policy_vehicles, 0, self.vehicles_count)
        shape = tuple(observation_shape) if isinstance(observation_shape, (list, tuple)) else None
        if shape is None or len(shape) != 2 or any(isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 8 for d in shape):
            raise ValueError(f"observation_shape must be two ints >= 8 (height, width), got {observation_shape!r}")
        self.observation_shape = (int(shape[0]), int(shape[1]))
        self.stack_size = _int_arg("stack_size", stack_size, 1)
        self.frame_scale = _float_arg("frame_scale", frame_scale, 0.5, 8.0)  # pixels per metre
        # Grayscale frames drawn at k x the resolution and block-averaged (anti-aliased; rendering.py).
        self.frame_supersample = _int_arg("frame_supersample", frame_supersample, 1, 8)
        # Policy steps between two stacked frames: the stack spans (stack_size - 1) x frame_interval steps,
        # so a speed difference moves a car frame_interval times as many pixels between its frames.
        self.frame_interval = _int_arg("frame_interval", frame_interval, 1, 30)
        # The ego's place across the frame's width (world x; 0.5 centred, highway-env's 0.3 shows more ahead).
        self.frame_centering = _float_arg("frame_centering", frame_centering, 0.0, 1.0, lo_open=True, hi_open=True)
        self.vehicles_observed = _int_arg("vehicles_observed", vehicles_observed, 0)
        if not isinstance(lane_features, (bool, np.bool_)):
            raise ValueError(f"lane_features must be True or False, got {lane_features!r}")
        self.lane_features = bool(lane_features)
        if not isinstance(alongside_features, (bool, np.bool_)):
            raise ValueError(f"alongside_features must be True or False, got {alongside_features!r}")
        if alongside_features and not lane_features:
            raise ValueError("alongside_features extends the lane features: it needs lane_features=True")
        self.alongside_features = bool(alongside_features)
        if not isinstance(gap_features, (bool, np.bool_)):
            raise ValueError(f"gap_features must be True or False, got {gap_features!r}")
        if gap_features and not lane_features:
            raise ValueError("gap_features extends the lane features: it needs lane_features=True")
        self.gap_features = bool(gap_features)
        if not isinstance(shield, (bool, np.bool_)):
            raise ValueError(f"shield must be True or False, got {shield!r}")
        if shield and action_set != "paper":
            raise ValueError("shield guards the paper action set (action_set='paper')")
        self.shield = bool(shield)
        self.speed_step = _float_arg("speed_step", speed_step, 0.0)
        self.curvature_step = _float_arg("curvature_step", curvature_step, 0.0, 2.0 / Vehicle.LENGTH)
        self.ego_speed_spread = _float_arg("ego_speed_spread", ego_speed_spread, 0.0)
        self.min_gap = _float_arg("min_gap", min_gap, Vehicle.LENGTH)
        self.ego_clearance = _float_arg("ego_clearance", ego_clearance, Vehicle.LENGTH)
        self.policy_frequency = _int_arg("policy_frequency", policy_frequency, 1)
        self.simulation_frequency = _int_arg("simulation_frequency", simulation_frequency, 1)
        if self.simulation_frequency % self.policy_frequency:
            raise ValueError(
                f"simulation_frequency ({simulation_frequency}) must be a multiple of policy_frequency ({policy_frequency})"
            )
        self.meta_target_speeds = np.asarray([_float_arg("meta_target_speeds", v, 0.0, AgentVehicle.MAX_SPEED) for v in meta_target_speeds])
        if self.meta_target_speeds.size == 0:
            raise ValueError("meta_target_speeds must not be empty")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.observation_type = observation
        self.action_set = action_set
        gap = _float_arg("shield_gap", shield_gap, 0.0, lo_open=True)
        decel = _float_arg("shield_decel", shield_decel, 0.0, self.speed_step * self.policy_frequency, lo_open=True)
        self.gap_shield = GapShield(self.speed_step, self.curvature_step, 1.0 / self.policy_frequency,
                                    AgentVehicle.LENGTH, buffer=gap, decel=decel) if self.shield else None

        # ---- spaces ---------------------------------------------------------------------------
        self.actions = paper_actions(self.speed_step, self.curvature_step)
        self.action_space = spaces.Discrete(len(self.actions) if action_set == "paper" else len(META_ACTIONS))
        self.vector_dim = vector_size(self.vehicles_observed, self.lane_features, self.alongside_features,
                                      self.gap_features)
        self.vector_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, shape=(self.vector_dim,), dtype=np.float32)
        if observation == "vector":
            self.observation_space = self.vector_space
        else:
            self.observation_space = spaces.Box(0, 255, shape=(self.stack_size, *self.observation_shape), dtype=np.uint8)

        # ---- simulation objects -----------------------------------------------------------------
        self.dt = 1.0 / self.simulation_frequency
        self.substeps = self.simulation_frequency // self.policy_frequency
        self.traffic = Traffic(self.layout, list(self.lane_speeds), self.layout.window_back, self.layout.window_front)
        self.road = Road(network=self.layout.network)
        self.ego: AgentVehicle | None = None
        self.agents: list[AgentVehicle] = []
        self.policy_vehicle_crashes = 0
        self.npc_policy: NpcPolicy | None = None
        self.target_lane = 0
        self.steps = 0
        self.time = 0.0
        self.anchor = np.zeros(n_all)
        # The last (stack_size - 1) x frame_interval + 1 frames, oldest first; every frame_interval-th is observed.
        self._frames: np.ndarray | None = None
        self._obs_renderer: TopDownRenderer | None = None
        self._rgb_renderer: TopDownRenderer | None = None
        self._last_info: dict[str, Any] = {}

    # ------------------------------------------------------------------------------------------
    # public helpers
    # ------------------------------------------------------------------------------------------
    def set_npc_policy(self, fn: NpcPolicy | None) -> None:
        """Drive the policy vehicles with ``fn``: float32 [N, obs_dim] vector observations (each
        from that vehicle's own perspective, one row per active policy vehicle, so N <= the
        ``policy_vehicles`` kwarg) -> int actions [N] of this env's action set.  Policy vehicles
        always get the vector observation, also when the ego observation is ``"grayscale"``.
        ``None`` restores the default (keep lane at constant speed)."""
        if fn is not None and not callable(fn):
            raise ValueError(f"fn must be callable or None, got {fn!r}")
        self.npc_policy = fn

    @property
    def vehicle(self) -> AgentVehicle | None:
        """The ego vehicle (highway-env's name for it)."""
        return self.ego

    def npc_vehicles(self) -> list[Vehicle]:
        """The constant-speed traffic as highway-env `Vehicle` objects (a snapshot, for inspection)."""
        out = []
        for x, y, h, v in zip(self.traffic.x, self.traffic.y, self.traffic.h, self.traffic.speed):
            veh = Vehicle(None, [x, y], float(h), float(v))
            veh.road = self.road
            out.append(veh)
        return out

    # ------------------------------------------------------------------------------------------
    # gymnasium API
    # ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"initial_lane", "target_lane"}
        if unknown:
            raise ValueError(f"options: unknown keys {sorted(unknown)} (allowed: initial_lane, target_lane)")
        rng = self.np_random
        layout = self.layout
        target = options.get("target_lane", self.target_lane_option)
        if target == "random":
            target = int(rng.choice(layout.spawn_lanes))
        self.target_lane = _int_arg("target_lane", target, 0, layout.lanes_count - 1)
        initial = options.get("initial_lane", self.initial_lane)
        if initial == "random":
            lane = int(rng.choice(layout.spawn_lanes))
        elif initial == "non-target":
            choices = [lane for lane in layout.spawn_lanes if lane != self.target_lane]
            if not choices:
                raise ValueError("initial_lane: 'non-target' but the target is the only lane")
            lane = int(rng.choice(choices))
        elif isinstance(initial, (int, np.integer)) and int(initial) in layout.spawn_lanes:
            lane = int(initial)
        else:
            raise ValueError(f"initial_lane: invalid {initial!r}")

        # Ego vehicle at the lane's start station, aligned with it.
        path = layout.paths[lane]
        s0 = layout.start_s[lane]
        x, y, h = (float(a[0]) for a in path.position(np.array([s0])))
        base_speed = self.lane_speeds[lane] if lane in layout.npc_lanes else self.lane_speeds[layout.ramp_speed_lane]
        speed = float(base_speed + rng.uniform(-self.ego_speed_spread, self.ego_speed_spread))
        self.ego = AgentVehicle(layout, x, y, h, max(speed, 0.0), kind="ego")
        self.ego.road = self.road
        self._locate(self.ego)
        self.anchor = np.array(self.ego.loc.s)

        # Constant-speed traffic, evenly split over the traffic lanes.
        npc_lanes = layout.npc_lanes
        split = np.full(len(npc_lanes), self.vehicles_count // len(npc_lanes))
        split[: self.vehicles_count % len(npc_lanes)] += 1
        per_lane = dict(zip(npc_lanes, split.tolist()))
        self.traffic.populate(rng, per_lane, list(self.anchor), lane, self.min_gap, self.ego_clearance)
        self.traffic.place(self.anchor)

        self._spawn_policy_vehicles(rng)
        self.road.vehicles = [self.ego, *self.agents]
        for v in self.road.vehicles:
            self._meta_targets(v)

        self.steps = 0
        self.time = 0.0
        self._frames = None
        obs = self._observe()
        info = self._info(crashed=False, collided=False, terms=None)
        return obs, info

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self.ego is None:
            raise RuntimeError("call reset() before step()")
        a = int(action)
        if not 0 <= a < self.action_space.n:
            raise ValueError(f"action must be in [0, {self.action_space.n}), got {action!r}")
        agent_actions = self._policy_actions()
        executed = self._shielded(self.ego, a)
        self._command(self.ego, executed)
        for agent, act in zip(self.agents, agent_actions):
            if agent.active:
                self._command(agent, int(act))

        collided = offroad = False
        for _ in range(self.substeps):
            if self.action_set == "meta":
                for v in (self.ego, *self.agents):
                    if v.active:
                        self._meta_control(v)
            self.ego.step(self.dt)
            for agent in self.agents:
                if agent.active:
                    agent.step(self.dt)
            self.traffic.advance(self.dt)
            self._locate(self.ego)
            for i, s in enumerate(self.ego.loc.s):
                self.anchor[i] = s
            self.traffic.place(self.anchor)
            collided, offroad = self._check_ego()
            self._check_agents()
            if collided or offroad:
                break
        self.steps += 1
        self.time += 1.0 / self.policy_frequency

        crashed = collided or offroad
        self.ego.crashed = crashed
        loc = self.ego.loc
        forward_speed = self.ego.speed * math.cos(self.ego.heading - loc.heading[loc.lane])
        moving, stopped = motion_flags(self.ego.speed, forward_speed)
        reward, terms = compute_reward(
            self.preset, crashed=crashed, moving_forward=moving, stopped=stopped,
            on_target_lane=loc.lane == self.target_lane,
        )
        obs = self._observe()
        terminated = crashed
        truncated = (not terminated) and self.steps >= self.max_steps
        info = self._info(crashed=crashed, collided=collided, terms=terms, offroad=offroad)
        if self.gap_shield is not None:
            info["shielded"] = executed != a  # the shield replaced this step's action
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self.ego is None:
            return None
        if self._rgb_renderer is None:
            self._rgb_renderer = TopDownRenderer(self.layout, (300, 600), 5.0, grayscale=False)
        return self._draw(self._rgb_renderer)

    def close(self) -> None:
        self._obs_renderer = self._rgb_renderer = None

    # ------------------------------------------------------------------------------------------
    # internals
    # ------------------------------------------------------------------------------------------
    def _locate(self, v: AgentVehicle) -> None:
        v.loc = locate(self.layout, float(v.position[0]), float(v.position[1]), v.hints)

    def _others(self, exclude: AgentVehicle) -> tuple[np.ndarray, ...]:
        t = self.traffic
        extra = [a for a in (self.ego, *self.agents) if a is not exclude and a.active]
        if not extra:
            return t.x, t.y, t.h, t.speed, t.lane
        return (
            np.concatenate([t.x, [a.position[0] for a in extra]]),
            np.concatenate([t.y, [a.position[1] for a in extra]]),
            np.concatenate([t.h, [a.heading for a in extra]]),
            np.concatenate([t.speed, [a.speed for a in extra]]),
            np.concatenate([t.lane, [a.loc.lane for a in extra]]),
        )

    def _shield_view(self, v: AgentVehicle) -> ShieldView:
        offset, rel, curvature = lane_errors(v.loc, v.loc.lane, v.heading)
        slots = self.lane_slots(v)
        return ShieldView(v.speed, offset, rel, curvature, v.loc.lane_end, self.layout.paths[v.loc.lane].width,
                          (slots[0], slots[1], slots[2]))

    def _shielded(self, v: AgentVehicle, action: int) -> int:
        """What ``v`` executes for ``action``: the shield's replacement where it has one (with
        ``shield``), else ``action``. The ego vehicle and the policy vehicles driven by the agent's
        policy (copies of the agent, shield included) go through it."""
        return action if self.gap_shield is None else self.gap_shield.safe_action(action, self._shield_view(v))

    def _vector_obs(self, v: AgentVehicle) -> np.ndarray:
        ox, oy, oh, ov, ol = self._others(v)
        return vector_observation(
            float(v.position[0]), float(v.position[1]), v.heading, v.speed, v.loc,
            self.layout.paths[v.loc.lane].width, self.layout.lanes_count, self.target_lane, self.curvature_step,
            ox, oy, oh, ov, ol, self.vehicles_observed,
            self._lane_features(v) if self.lane_features else None,
        )

    def _observe(self) -> np.ndarray:
        if self.observation_type == "vector":
            return self._vector_obs(self.ego)
        if self._obs_renderer is None:
            self._obs_renderer = TopDownRenderer(self.layout, self.observation_shape, self.frame_scale, grayscale=True,
                                                 supersample=self.frame_supersample, centering=self.frame_centering)
        frame = self._draw(self._obs_renderer)
        if self._frames is None:  # first frame of an episode fills the whole history
            self._frames = np.repeat(frame[None], (self.stack_size - 1) * self.frame_interval + 1, axis=0)
        else:
            self._frames = np.roll(self._frames, -1, axis=0)
            self._frames[-1] = frame
        return self._frames[::self.frame_interval].copy()  # the newest frame is last whatever the interval

    def _draw(self, renderer: TopDownRenderer) -> np.ndarray:
        t = self.traffic
        agents = [a for a in self.agents if a.active]
        vehicles = [(t.x, t.y, t.h, "npc")]
        if agents:
            vehicles.append((
                np.array([a.position[0] for a in agents]), np.array([a.position[1] for a in agents]),
                np.array([a.heading for a in agents]), "policy",
            ))
        e = self.ego
        vehicles.append((np.array([e.position[0]]), np.array([e.position[1]]), np.array([e.heading]), "ego"))
        return renderer.render((float(e.position[0]), float(e.position[1])), self.target_lane, vehicles, Vehicle.LENGTH, Vehicle.WIDTH)

    def _check_ego(self) -> tuple[bool, bool]:
        e = self.ego
        t = self.traffic
        hit = collisions(float(e.position[0]), float(e.position[1]), e.heading, e.LENGTH, e.WIDTH, t.x, t.y, t.h)
        collided = hit.size > 0
        for a in self.agents:
            if a.active and collisions(
                float(e.position[0]), float(e.position[1]), e.heading, e.LENGTH, e.WIDTH,
                a.position[:1], a.position[1:], np.array([a.heading]),
            ).size:
                collided = True
                a.crashed = True
        offroad = not e.loc.on_road
        e.offroad = offroad
        return collided, offroad

    def _info(self, *, crashed: bool, collided: bool, terms: dict[str, float] | None, offroad: bool = False) -> dict[str, Any]:
        loc = self.ego.loc
        if terms is None:  # reset: no step taken yet
            terms = dict.fromkeys(REWARD_TERM_NAMES, 0.0)
        return {
            "crashed": bool(crashed),
            "collided": bool(collided),
            "offroad": bool(offroad),
            "on_target_lane": bool(loc.lane == self.target_lane),
            "lane_index": int(loc.lane),
            "target_lane": int(self.target_lane),
            "speed": float(self.ego.speed),
            "reward_terms": terms,
            "steps": self.steps,
            "policy_vehicles_active": sum(a.active for a in self.agents),
            "policy_vehicle_crashes": self.policy_vehicle_crashes,  # this episode's, so far
        }


def road_env(scenario: str, max_steps: int, vehicles: int, doc: str) -> type[LaneChangeEnv]:
    """The env class registered for one road: ``LaneChangeEnv`` on ``scenario``'s layout, with that
    road's default episode length and traffic count."""
    name = f"{scenario.capitalize()}LaneChangeEnv"
    return type(name, (LaneChangeEnv,), {"__doc__": doc, "__module__": __name__, "__qualname__": name,
                                         "SCENARIO": scenario, "DEFAULT_MAX_STEPS": max_steps,
                                         "DEFAULT_VEHICLES": vehicles})


StraightLaneChangeEnv = road_env("straight", 300, 30, "Fig. 3(a), the evaluation task: straight road, 300-step "
                                 "episodes by default.")
MergeLaneChangeEnv = road_env("merge", 100, 20, "Fig. 3(b): merge from an ending on-ramp into the main road "
                              "(reward-study length 100).")
CurveLaneChangeEnv = road_env("curve", 100, 30, "Fig. 3(c): lane change on a winding road (reward-study length 100).")
RoundaboutLaneChangeEnv = road_env("roundabout", 100, 96, "Fig. 3(d): lane change on a multi-lane ring "
                                   "(reward-study length 100).")
