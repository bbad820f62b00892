"""Where a network crashes: on validation episodes (episode seeds 200,000 on, random initial lane, 300
steps), at each collision the hit car's position relative to the ego (ahead or behind, in the ego's lane
or not, after a lane change in the last 1.5 s or not), its distance dx (m) and speed gap dv (m/s, the
car's speed minus the ego's); the other episodes as achieved, survived in another lane, or off the road.

    python crash_geometry.py CHECKPOINT EPISODES

Room: a study script (docs/results). May import: anything in laneshift, numpy.
"""
import collections
import sys

import numpy as np

from laneshift.actors.evaluation import checkpoint_env_settings, load_checkpoint_policy
from laneshift.actors.envs.lane_change import LaneChangeEnv
from laneshift.actors.envs.traffic import collisions


def classify(env, info: dict, lanes_seen: list[int]) -> tuple[str, float | None, float | None]:
    """How an episode ended: the hit car's place (ahead or behind, the ego's lane or not, after a lane
    change in the last 1.5 s), its distance and speed gap; or off the road, achieved, another lane."""
    if info.get("collided"):
        e, tr = env.ego, env.traffic
        hit = np.asarray(collisions(float(e.position[0]), float(e.position[1]), e.heading, e.LENGTH, e.WIDTH,
                                    tr.x, tr.y, tr.h)).reshape(-1)
        if not hit.size:
            return "collided (policy car)", None, None
        j = int(hit[0])
        dx, dv = float(tr.x[j] - e.position[0]), float(tr.speed[j] - e.speed)
        where = "ahead" if dx > 0 else "behind"
        lane = " same-lane" if int(tr.lane[j]) == info["lane_index"] else " other-lane"
        change = " after-change" if len(set(lanes_seen[-15:])) > 1 else ""
        return where + lane + change, dx, dv
    if info.get("offroad"):
        return "offroad", None, None
    return ("achieved" if info.get("on_target_lane") else "survived, other lane"), None, None


def main(checkpoint: str, episodes: int) -> None:
    policy = load_checkpoint_policy(checkpoint)
    act = policy.greedy()
    # The env the network was trained in, as far as its checkpoint says (observation, frame supersampling).
    env_kwargs = {k: v for k, v in checkpoint_env_settings(policy.meta).items() if k != "scenario"}
    stats: collections.Counter = collections.Counter()
    rows = []
    for ep in range(episodes):
        env = LaneChangeEnv(**env_kwargs, initial_lane="random")
        obs, info = env.reset(seed=200000 + ep)
        lanes_seen: list[int] = []
        for t in range(300):
            obs, _, terminated, truncated, info = env.step(int(act(obs)))
            lanes_seen.append(info["lane_index"])
            if terminated or truncated:
                break
        key, dx, dv = classify(env, info, lanes_seen)
        stats[key] += 1
        if dx is not None:
            rows.append((ep, t, key, round(dx, 1), round(dv, 1)))
    print(dict(stats))
    for row in rows[:30]:
        print(row)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
