"""Scripted demonstrators with privileged access to the simulator state.

* :class:`ScriptedDriver` drives the lane-change scenarios with the paper's 9 actions: it keeps a
  braking-safe distance to the vehicles ahead and a catch-up-safe distance to the (non-braking)
  vehicles behind, lines up with a gap in the next lane towards the target, changes lane when
  the gap is safe for the whole manoeuvre, and steers back onto lane centres.
* :class:`LKAExpert` drives the MATLAB LKA plant: a discrete LQR whose cost is the env's reward
  (10 e1^2 + 5 e2^2 + 2 u^2 + 5 de1^2 + 5 de2^2) plus steady-state feed-forward for the road
  curvature, rounded to the nearest of the 31 steering actions.

Both are called as ``action = driver(obs)`` and read ``env.unwrapped`` for the real state; on
``allroads`` the lane-change drivers read the current episode's road env (``road_env``).

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from .actions import SPEED_CHANGES
from .allroads import AllRoadsLaneChangeEnv
from .control import curvature_index, lane_errors, speed_index
from .lane_change import LaneChangeEnv
from .lka import LKA_STEERING_DEG, LaneKeepingAssistEnv, discrete_model
from .observations import nearest_gap_middle


def _road_env(source: gym.Env) -> LaneChangeEnv:
    """The lane-change env a driver reads: ``source`` itself, or allroads' road of this episode."""
    return source.road_env if isinstance(source, AllRoadsLaneChangeEnv) else source


def _towards(lane: int, target: int) -> int:
    """The next lane from ``lane`` towards ``target`` (``lane != target``)."""
    return lane + (1 if target > lane else -1)


class ScriptedDriver:
    """Rule-based lane-change driver for `LaneChangeEnv` (paper action set).

    Parameters: ``decel`` is the deceleration [m/s^2] it plans with (the paper's 0.1 m/s per step
    at 10 Hz gives at most 1 m/s^2); ``buffer`` the bumper-to-bumper distance [m] it keeps;
    ``change_time`` the lane-change duration [s] over which a gap must stay free;
    ``runway_margin`` the room [m] kept beyond what speeding up to a faster target lane takes.
    """

    #: Bumped when the driving changes, so default demo shards of an older driver are not reused.
    #: 2: hangs back from a slower leader before merging into a faster lane; plans with 0.9 m/s^2.
    VERSION = 2

    def __init__(self, env: gym.Env, decel: float = 0.9, buffer: float = 3.0, change_time: float = 3.5,
                 runway_margin: float = 2.0) -> None:
        base = env.unwrapped
        if not isinstance(_road_env(base), LaneChangeEnv):
            raise ValueError(f"env must be a laneshift lane-change env, got {type(base).__name__}")
        if _road_env(base).action_set != "paper":
            raise ValueError("ScriptedDriver drives the paper action set (action_set='paper')")
        self.source = base
        self.decel = decel
        self.buffer = buffer
        self.change_time = change_time
        self.runway_margin = runway_margin
        self.plan_lane: int | None = None
        self._episode_key: Any = None

    @property
    def env(self) -> LaneChangeEnv:
        """The env whose state it reads: the one it was given, or allroads' road of this episode."""
        return _road_env(self.source)

    # ------------------------------------------------------------------------------------------
    def __call__(self, obs: Any = None) -> int:
        env = self.env
        ego = env.ego
        loc = ego.loc
        if self._episode_key is not ego:  # new episode: forget the previous plan
            self._episode_key = ego
            self.plan_lane = None
        lane = loc.lane
        target = env.target_lane
        if self.plan_lane is None or self.plan_lane == lane:
            self.plan_lane = lane
        # Decide whether to move one lane towards the target.
        if self.plan_lane == lane and lane != target:
            cand = _towards(lane, target)
            if env.lanes_adjacent(loc, lane, cand) and self._gap_safe(cand):
                self.plan_lane = cand
        elif self.plan_lane != lane and abs(loc.lat[lane]) < 1.0 and not self._gap_safe(self.plan_lane):
            self.plan_lane = lane  # barely started and the gap closed: abort
        # Longitudinal.
        desired = self._desired_speed(lane, target)
        s_idx = speed_index(ego.speed, desired)
        # Lateral: steer onto the planned lane's centre.
        offset, rel, curv = lane_errors(loc, self.plan_lane, ego.heading)
        step_len = max(ego.speed, 1.0) / env.policy_frequency
        c_idx = curvature_index(offset, rel, curv, step_len, env.curvature_step)
        return 3 * s_idx + c_idx

    # ------------------------------------------------------------------------------------------
    def _neighbours(self, lane: int) -> tuple[float, float, float, float]:
        """(gap ahead, speed ahead, gap behind, speed behind) on ``lane``, bumper to bumper [m]."""
        return self.env.lane_neighbours(self.env.ego, lane)

    def _gap_safe(self, lane: int) -> bool:
        """Is ``lane`` free around the ego vehicle during the whole lane change, and can the ego
        vehicle then settle behind its new leader / ahead of its new follower?

        The ego vehicle is assumed to move its speed towards the lane's traffic speed at
        ``decel`` during the ``change_time`` seconds of the manoeuvre (what :meth:`__call__` does).
        """
        env = self.env
        ego = env.ego
        s_occ, v_occ = env.lane_occupants(lane, exclude=ego)
        if s_occ.size == 0:
            return True
        s_e = ego.loc.s[lane]
        v_e = ego.speed
        d0 = np.array([env.lane_gap(lane, s_e, float(s)) for s in s_occ])
        near = np.abs(d0) < 80.0
        d0, v = d0[near], v_occ[near]
        if d0.size == 0:
            return True
        t = np.linspace(0.0, self.change_time, 21)
        dv = self._lane_speed(lane) - v_e
        t_match = abs(dv) / self.decel
        tc = np.minimum(t, t_match)
        ego_x = v_e * t + math.copysign(1.0, dv) * (self.decel * tc * tc / 2 + self.decel * tc * (t - tc))
        ego_v = v_e + math.copysign(1.0, dv) * self.decel * tc[-1]
        gaps = d0[:, None] + v[:, None] * t[None, :] - ego_x[None, :]
        need = ego.LENGTH + self.buffer
        if np.any(np.abs(gaps) < need) or np.any(np.sign(gaps[:, :1]) != np.sign(gaps)):
            return False
        # After the change: room to brake to a slower leader / speed up to a faster follower.
        end = np.abs(gaps[:, -1]) - need
        closing = np.where(gaps[:, -1] > 0, ego_v - v, v - ego_v)
        return not np.any((closing > 0) & (end < closing * closing / (2 * self.decel)))

    def _bounds(self, lane: int) -> tuple[float, float]:
        """(lowest, highest) safe speed on ``lane`` given its leader and follower."""
        front, v_front, rear, v_rear = self._neighbours(lane)
        hi, lo = math.inf, 0.0
        if math.isfinite(front):
            hi = v_front + math.sqrt(2 * self.decel * max(front - self.buffer, 0.0))
        if math.isfinite(rear):
            lo = v_rear - math.sqrt(2 * self.decel * max(rear - self.buffer, 0.0))
        return lo, hi

    def _desired_speed(self, lane: int, target: int) -> float:
        env = self.env
        ego = env.ego
        loc = ego.loc
        lanes = {lane, self.plan_lane}
        # Lanes the ego body overlaps (mid lane change).
        for other in (lane - 1, lane + 1):
            if 0 <= other < env.layout.lanes_count and loc.inside[other] and abs(loc.lat[other]) < 3.2:
                lanes.add(other)
        lo, hi = 0.0, math.inf
        for ln in lanes:
            a, b = self._bounds(ln)
            lo, hi = max(lo, a), min(hi, b)
        # Waiting on this lane to move one lane towards the target (always a lane of the road).
        cand = _towards(lane, target) if self.plan_lane == lane and lane != target else None
        if cand is not None:
            hi = min(hi, self._runway_cap(lane, self._lane_speed(cand)))
        if math.isfinite(loc.lane_end):  # the merge ramp ends: be able to stop before its end
            hi = min(hi, math.sqrt(2 * self.decel * max(loc.lane_end - ego.LENGTH, 0.0)))
        flow = self._lane_speed(self.plan_lane)
        desired = flow
        if cand is not None:
            if loc.inside[cand]:
                desired = self._align_speed(cand)
        elif self.plan_lane == lane:
            front, _, rear, _ = self._neighbours(lane)
            if math.isfinite(front) and math.isfinite(rear):  # drift to the middle of the gap
                desired = flow + 0.05 * (front - rear)
        if lo > hi:  # squeezed between a slower leader and a faster follower
            return 0.5 * (lo + hi)
        return min(max(desired, lo), hi)

    def _runway_cap(self, lane: int, cand_speed: float) -> float:
        """Highest speed on ``lane`` that keeps room ahead to speed up to a faster next lane.

        Merging into faster traffic means matching its speed during the change; stuck right
        behind a slower leader the ego vehicle cannot, and lets every gap go by. So it hangs
        back by the distance it gains on the leader while accelerating to ``cand_speed``.
        """
        front, v_front, _, _ = self._neighbours(lane)
        if not math.isfinite(front) or cand_speed <= v_front:
            return math.inf
        dv = cand_speed - v_front
        runway = dv * dv / (2 * self.decel) + self.runway_margin
        return v_front + math.sqrt(2 * self.decel * max(front - self.buffer - runway, 0.0))

    def _lane_speed(self, lane: int) -> float:
        speeds = self.env.lane_speeds
        if lane in self.env.layout.npc_lanes:
            return float(speeds[lane])
        return float(speeds[self.env.layout.ramp_speed_lane])

    def _align_speed(self, lane: int) -> float:
        """Speed that brings the ego vehicle level with the nearest usable gap of ``lane``."""
        env = self.env
        ego = env.ego
        s_occ, _ = env.lane_occupants(lane, exclude=ego)
        flow = self._lane_speed(lane)
        if s_occ.size == 0:
            return flow
        rel = np.sort([env.lane_gap(lane, ego.loc.s[lane], float(s)) for s in s_occ])
        best = nearest_gap_middle(rel, 2 * (ego.LENGTH + self.buffer) + 4.0)
        return flow + max(-3.0, min(3.0, 0.15 * best))


class KeepLaneDriver:
    """Baseline: constant speed, steering only to stay on the current lane's centre."""

    def __init__(self, env: gym.Env) -> None:
        self.source = env.unwrapped

    def __call__(self, obs: Any = None) -> int:
        env = _road_env(self.source)
        ego = env.ego
        offset, rel, curv = lane_errors(ego.loc, ego.loc.lane, ego.heading)
        step_len = max(ego.speed, 1.0) / env.policy_frequency
        return 3 * SPEED_CHANGES.index(0) + curvature_index(offset, rel, curv, step_len, env.curvature_step)


class LKAExpert:
    """Discrete LQR for `LaneKeepingAssistEnv`, quantised to the 31 steering actions."""

    def __init__(self, env: gym.Env, iterations: int = 2000) -> None:
        base = env.unwrapped
        if not isinstance(base, LaneKeepingAssistEnv):
            raise ValueError(f"env must be LaneKeepingAssist-v0, got {type(base).__name__}")
        self.env = base
        p = base.params
        Ad, Bd, Ed = discrete_model(p)
        A, B, E = Ad[:4, :4], Bd[:4, None], Ed[:4]
        # Cost = reward terms on the next state: rows e1, e2, de1 = vy + Vx e2, de2 = r (- Vx rho).
        C = np.array([[0, 0, 1, 0], [0, 0, 0, 1], [1, 0, 0, p.Vx], [0, 1, 0, 0]], dtype=np.float64)
        W = np.diag([10.0, 5.0, 5.0, 5.0])
        Q, R = C.T @ W @ C, np.array([[2.0]])
        P = Q.copy()
        for _ in range(iterations):
            K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
            P = Q + A.T @ P @ (A - B @ K)
        self.K = K.ravel()
        # Steady state on the curve with e1 = 0: x = A x + B u + E rho, unknowns (vy, r, e2, u).
        M = np.column_stack([(np.eye(4) - A)[:, 0], (np.eye(4) - A)[:, 1], (np.eye(4) - A)[:, 3], -B[:, 0]])
        vy, r, e2, u = np.linalg.solve(M, E * p.rho)
        self.x_ss = np.array([vy, r, 0.0, e2])
        self.u_ss = float(u)

    def __call__(self, obs: Any = None) -> int:
        x = self.env.state[:4]
        u = self.u_ss - float(self.K @ (x - self.x_ss))
        deg = int(np.clip(np.rint(np.rad2deg(u)), LKA_STEERING_DEG[0], LKA_STEERING_DEG[-1]))
        return deg - LKA_STEERING_DEG[0]
