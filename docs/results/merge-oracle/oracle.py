"""How many of merge's episodes from a non-target lane can be solved at all behind the shield: a search
with the simulator's state (an upper reference for a policy; it looks ahead by copying the env).

The lane-change env is deterministic after its reset (constant-speed traffic, no randomness in
``step``), so a copy of it is an exact model of the episode. For each episode the published
networks and the scripted driver drive it first; an episode none of them solves goes to the
search, which tries, from the start, a family of simple plans until one ends the 300 steps alive
on the target lane:

* the scripted driver with other figures (change time, buffer, planning deceleration);
* a speed plan (a desired speed held to a switch time, another after it; 1-16 m/s) with the
  steering either pressing towards the target lane all the time (the shield holds it back while
  the lane is not free by its rule) or only while the shield's rule calls that lane free.
  In the target lane it keeps the lane at its traffic's speed.

Every plan drives behind the same shield as the agents, so what the search solves an agent behind
the shield could solve. What it does not solve is not proven unsolvable (the family is finite), so
the search's rate is a lower bound on what the road allows and an upper reference for the agents.

    python docs/results/merge-oracle/oracle.py --seed0 200000 --episodes 200 --out DIR

Room: a study's script beside its results (run by path, not installed). May import: laneshift, numpy.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import json
import time
from pathlib import Path

from laneshift.actors.envs import make
from laneshift.actors.envs.control import curvature_index, lane_errors, speed_index
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.actors.evaluation import load_greedy_policy
from laneshift.config import EnvConfig
from laneshift.demos.outcomes import episode_outcome
from laneshift.tools.demos.drivers import drive_to_end

CHECKPOINTS = "results/checkpoints/merge-pre60k-dqfd-bc-alongside-gaps-safe-shield-seed{}-final.safetensors"
ENV = EnvConfig(scenario="merge", max_steps=300, alongside_features=True, gap_features=True, shield=True,
                initial_lane="non-target")


class SpeedPlan:
    """Desired speed ``v1`` before step ``switch``, ``v2`` after it, until the target lane is reached;
    steering towards the target lane (``press``) or towards it only while the shield calls it free."""

    def __init__(self, env, v1: float, v2: float, switch: int, press: bool) -> None:
        self.env, self.v1, self.v2, self.switch, self.press = env, v1, v2, switch, press

    def __call__(self, obs=None) -> int:
        u = self.env
        ego = u.ego
        loc = ego.loc
        lane, target = loc.lane, u.target_lane
        plan = lane
        desired = float(u.lane_speeds[target])
        if lane != target:
            desired = self.v1 if u.steps < self.switch else self.v2
            cand = lane + (1 if target > lane else -1)
            if u.lanes_adjacent(loc, lane, cand):
                side = 1 if u.adjacent_lane(ego, -1) == cand else 2
                if self.press or u.gap_shield.lane_free(u.lane_slots(ego)[side]):
                    plan = cand
        offset, rel, curv = lane_errors(loc, plan, ego.heading)
        step_len = max(ego.speed, 1.0) / u.policy_frequency
        return 3 * speed_index(ego.speed, desired) + curvature_index(offset, rel, curv, step_len, u.curvature_step)


def plans():
    """(name, factory(env) -> policy), simplest first."""
    for change_time, buffer, decel in itertools.product((3.5, 2.5, 1.5), (3.0, 2.0), (0.9, 1.0)):
        yield (f"driver change_time={change_time} buffer={buffer} decel={decel}",
               lambda e, c=change_time, b=buffer, d=decel: ScriptedDriver(e, decel=d, buffer=b, change_time=c))
    speeds = range(1, 17)
    for press in (False, True):
        for v in speeds:
            yield f"speed {v} press={press}", lambda e, v=v, p=press: SpeedPlan(e, v, v, 0, p)
    for press in (False, True):
        for switch, v1, v2 in itertools.product((30, 60, 100, 150, 200), range(2, 17, 2), range(2, 17, 2)):
            if v1 != v2:
                yield (f"speed {v1} then {v2} from step {switch} press={press}",
                       lambda e, s=switch, a=v1, b=v2, p=press: SpeedPlan(e, a, b, s, p))


def drive(env, policy, obs) -> dict:
    """Drive ``env`` (already reset; ``obs`` its observation) to the end with ``policy``: the demo tools' episode
    loop, and the paper's outcome of its last step (a crash on the target lane is no achievement)."""
    episode = drive_to_end(env, policy, obs, {})
    outcome = episode_outcome(episode["infos"][-1])
    survived = not outcome["crashed"]
    return {"survived": survived, "achieved": survived and outcome["on_target_lane"], "steps": len(episode["actions"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed0", type=int, required=True)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--networks", default="0,1,2", help="seeds of the published networks ('' for none)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    nets = {f"seed{s}": load_greedy_policy(CHECKPOINTS.format(s)) for s in args.networks.split(",") if s}
    env = make(ENV)
    u = env.unwrapped
    rows = []
    started = time.time()
    for ep in range(args.episodes):
        seed = args.seed0 + ep
        row: dict = {"seed": seed}
        obs, info = env.reset(seed=seed)
        row["start_lane"] = info["lane_index"]
        start = copy.deepcopy(u)
        first_obs = obs
        for name, net in nets.items():
            row[name] = drive(copy.deepcopy(start), net, first_obs)["achieved"]
        sim = copy.deepcopy(start)
        row["driver"] = drive(sim, ScriptedDriver(sim), first_obs)["achieved"]
        row["search"] = None
        if not any(row[k] for k in (*nets, "driver")):
            tried = 0
            for name, factory in plans():
                sim = copy.deepcopy(start)
                tried += 1
                if drive(sim, factory(sim), first_obs)["achieved"]:
                    row["search"] = name
                    break
            row["plans_tried"] = tried
        row["solved"] = row["search"] is not None or any(row[k] for k in (*nets, "driver"))
        rows.append(row)
        print(json.dumps(row), f"[{time.time() - started:.0f} s]", flush=True)
    (args.out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    n = len(rows)
    summary = {"episodes": n, "seed0": args.seed0, "initial_lane": "non-target",
               **{k: 100.0 * sum(r[k] for r in rows) / n for k in (*nets, "driver", "solved")},
               "solved_by_search_only": sum(r["search"] is not None for r in rows),
               "unsolved_starts": {str(lane): sum(not r["solved"] and r["start_lane"] == lane for r in rows)
                                   for lane in sorted({r["start_lane"] for r in rows})}}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
