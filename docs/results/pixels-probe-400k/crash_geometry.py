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
ck, n = sys.argv[1], int(sys.argv[2])
cp = load_checkpoint_policy(ck); act = cp.greedy()
# The env the network was trained in, as far as its checkpoint says (observation, frame supersampling).
env_kwargs = {k: v for k, v in checkpoint_env_settings(cp.meta).items() if k != "scenario"}
stats = collections.Counter(); rows = []
for ep in range(n):
    env = LaneChangeEnv(**env_kwargs, initial_lane="random")
    o, info = env.reset(seed=200000 + ep)
    prev_lane = info["lane_index"]; lanes_seen = []
    for t in range(300):
        a = int(act(o))
        o, r, term, trunc, info = env.step(a)
        lanes_seen.append(info["lane_index"])
        if term or trunc: break
    if info.get("collided"):
        e, tr = env.ego, env.traffic
        hit = collisions(float(e.position[0]), float(e.position[1]), e.heading, e.LENGTH, e.WIDTH, tr.x, tr.y, tr.h)
        j = int(np.asarray(hit).reshape(-1)[0]) if np.asarray(hit).size else None
        if j is not None:
            dx = float(tr.x[j] - e.position[0]); dv = float(tr.speed[j] - e.speed)
            same = int(tr.lane[j]) == info["lane_index"]
            changed = len(set(lanes_seen[-15:])) > 1  # a lane change within the last 1.5 s
            key = ("ahead" if dx > 0 else "behind") + (" same-lane" if same else " other-lane") + (" after-change" if changed else "")
            stats[key] += 1; rows.append((ep, t, key, round(dx, 1), round(dv, 1)))
        else: stats["collided (policy car)"] += 1
    elif info.get("offroad"): stats["offroad"] += 1
    elif info.get("on_target_lane"): stats["achieved"] += 1
    else: stats["survived, other lane"] += 1
print(dict(stats))
for r in rows[:30]: print(r)
