"""The lane-change env's policy vehicles (``PolicyVehicles``, a base of
``lane_change.LaneChangeEnv``): copies of the agent that drive among the constant-speed traffic.
At reset they replace traffic vehicles away from the ego vehicle; each step they act through the
function given to ``set_npc_policy`` (on their own vector observations; behind the env's safety
shield when it has one, as the ego vehicle) or keep their lane; one that
crashes or leaves the traffic window comes back on a free spot away from the ego vehicle, or leaves
the scene when there is none.

Room: actors, the env-running component. May import: the contract and laneshift.actors; never
another component.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from highway_env.road.road import Road

from .scenarios import Layout
from .traffic import AgentVehicle, Traffic, collisions

NpcPolicy = Callable[[np.ndarray], Sequence[int] | np.ndarray]

#: Smallest distance [m] from the ego vehicle at which policy vehicles start or re-enter.
POLICY_SPAWN_DISTANCE = 40.0


class PolicyVehicles:
    """Spawning, acting and respawning of the policy vehicles (the env's ``agents``). Besides the
    state below it uses the env's lane queries (lanes.LaneQueries), its ``_keep_lane_action``
    (driving.Driving), ``_locate``, ``_vector_obs``, ``_shielded``, ``action_space`` and ``np_random``."""

    layout: Layout
    traffic: Traffic
    road: Road
    agents: list[AgentVehicle]
    anchor: np.ndarray
    policy_vehicles: int
    npc_policy: NpcPolicy | None
    lane_speeds: np.ndarray
    min_gap: float
    policy_vehicle_crashes: int  # this episode's crashes of policy vehicles (each respawned or gone)

    def _spawn_policy_vehicles(self, rng: np.random.Generator) -> None:
        """Policy vehicles replace randomly chosen traffic vehicles away from the ego vehicle."""
        self.agents = []
        self.policy_vehicle_crashes = 0
        if not self.policy_vehicles:
            return
        traffic = self.traffic
        rel = np.array([self.lane_gap(int(ln), self.anchor[ln], s) for ln, s in zip(traffic.lane, traffic.s)])
        far = np.flatnonzero(np.abs(rel) >= POLICY_SPAWN_DISTANCE)
        if far.size < self.policy_vehicles:
            far = np.argsort(-np.abs(rel))[: self.policy_vehicles]
        chosen = rng.choice(far, size=self.policy_vehicles, replace=False)
        for j in chosen:
            agent = AgentVehicle(
                self.layout, float(traffic.x[j]), float(traffic.y[j]), float(traffic.h[j]),
                float(traffic.speed[j]), kind="policy",
            )
            agent.road = self.road
            agent.hints = [p.segment_at(float(traffic.s[j])) for p in self.layout.paths]
            self._locate(agent)
            self.agents.append(agent)
        traffic.remove(chosen)
        traffic.place(self.anchor)

    def _policy_actions(self) -> list[int]:
        """One action per policy vehicle (inactive ones get 0 and are not simulated)."""
        active = [i for i, a in enumerate(self.agents) if a.active]
        actions = [0] * len(self.agents)
        if not active:
            return actions
        if self.npc_policy is None:
            for i in active:
                actions[i] = self._keep_lane_action(self.agents[i])
            return actions
        batch = np.stack([self._vector_obs(self.agents[i]) for i in active])
        out = np.asarray(self.npc_policy(batch)).reshape(-1)
        if out.size != len(active):
            raise ValueError(f"npc policy returned {out.size} actions for {len(active)} observations")
        for i, act in zip(active, out):
            act = int(act)
            if not 0 <= act < self.action_space.n:
                raise ValueError(f"npc policy returned action {act}, outside [0, {self.action_space.n})")
            actions[i] = self._shielded(self.agents[i], act)  # copies of the agent: behind its shield too
        return actions

    def _check_agents(self) -> None:
        """After a sub-step: each active policy vehicle located again; one that crashed (off the road,
        into traffic or into another policy vehicle) or left the traffic window is respawned."""
        if not self.agents:
            return
        t = self.traffic
        for a in self.agents:
            if not a.active:
                continue
            self._locate(a)
            x, y = float(a.position[0]), float(a.position[1])
            crashed = a.crashed or not a.loc.on_road
            if not crashed:
                crashed = collisions(x, y, a.heading, a.LENGTH, a.WIDTH, t.x, t.y, t.h).size > 0
            if not crashed:
                for b in self.agents:
                    if b is not a and b.active and collisions(
                        x, y, a.heading, a.LENGTH, a.WIDTH, b.position[:1], b.position[1:], np.array([b.heading])
                    ).size:
                        crashed = b.crashed = True
            lane = a.loc.lane
            path = self.layout.paths[lane]
            out = False
            if not path.closed:
                rel = a.loc.s[lane] - self.anchor[lane]
                out = rel < -self.traffic.back or rel > self.traffic.front
            self.policy_vehicle_crashes += crashed
            if crashed or out:
                self._respawn(a)

    def _respawn(self, a: AgentVehicle) -> None:
        """Put a crashed / out-of-window policy vehicle back on a free spot away from the ego vehicle."""
        rng = self.np_random
        layout = self.layout
        lanes = [ln for ln in layout.npc_lanes if ln in layout.spawn_lanes]
        a.crashed = False
        for _ in range(10):
            lane = int(rng.choice(lanes))
            path = layout.paths[lane]
            if path.closed:
                rel = rng.uniform(POLICY_SPAWN_DISTANCE, path.length - POLICY_SPAWN_DISTANCE)
            else:
                side = rng.integers(2)
                lo, hi = (POLICY_SPAWN_DISTANCE, self.traffic.front - 10.0) if side else (-self.traffic.back + 10.0, -POLICY_SPAWN_DISTANCE)
                rel = rng.uniform(lo, hi)
            s = self.anchor[lane] + rel
            occ_s, _ = self.lane_occupants(lane, exclude=a)
            if occ_s.size and np.min(np.abs([self.lane_gap(lane, s, o) for o in occ_s])) < self.min_gap:
                continue
            x, y, h = (float(v[0]) for v in path.position(np.array([s])))
            a.position = np.array([x, y])
            a.heading = h
            a.speed = float(self.lane_speeds[lane])
            a.hints = [p.segment_at(s) if p is path else a.hints[i] for i, p in enumerate(layout.paths)]
            a.action = {"steering": 0.0, "acceleration": 0.0}
            self._locate(a)
            self._meta_targets(a)
            return
        a.active = False  # no free spot: the vehicle leaves the scene
