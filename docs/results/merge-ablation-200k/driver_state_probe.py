"""Does the scripted driver's hidden state explain what a network cannot imitate? (diagnostic only)
Drives merge episodes with the ScriptedDriver, records the observation, the action and two things the
driver decides from and the observation lacks: its planned lane (relative to the current one) and its
gap test for the lane towards the target. Then trains the same MLP with and without them.

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch.
"""
import sys, numpy as np, torch
from laneshift.actors.envs import make
from laneshift.actors.envs.demonstrator import ScriptedDriver, _towards
from laneshift.config import EnvConfig
torch.set_num_threads(1)
n = int(sys.argv[1]) if len(sys.argv) > 1 else 300
env = make(EnvConfig(scenario="merge", max_steps=300)); drv = ScriptedDriver(env)
O, A, P, E = [], [], [], []
for ep in range(n):
    obs, info = env.reset(seed=10000 + ep); done = False
    while not done:
        a = drv(obs); u = drv.env; lane = u.ego.loc.lane; tgt = u.target_lane
        cand = _towards(lane, tgt) if lane != tgt else lane
        gap = float(lane != tgt and u.lanes_adjacent(u.ego.loc, lane, cand) and drv._gap_safe(cand))
        O.append(obs); A.append(a); P.append([drv.plan_lane - lane, gap]); E.append(ep)
        obs, r, term, trunc, info = env.step(a); done = term or trunc
O, A, P, E = np.array(O, np.float32), np.array(A), np.array(P, np.float32), np.array(E)
print(f"{len(A)} states from {n} episodes; plan != lane on {np.mean(P[:,0]!=0):.1%}, gap safe on {np.mean(P[:,1]):.1%}")
tr, te = E < int(0.8 * n), E >= int(0.8 * n)
for name, X in (("observation", O), ("observation + plan + gap test", np.concatenate([O, P], 1))):
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(X.shape[1], 256), torch.nn.ReLU(), torch.nn.Linear(256, 256), torch.nn.ReLU(), torch.nn.Linear(256, 9))
    opt = torch.optim.Adam(net.parameters(), 1e-3); Xt, Yt = torch.tensor(X[tr]), torch.tensor(A[tr])
    for epoch in range(15):
        perm = torch.randperm(len(Xt))
        for i in range(0, len(Xt), 256):
            idx = perm[i:i+256]; loss = torch.nn.functional.cross_entropy(net(Xt[idx]), Yt[idx]); opt.zero_grad(); loss.backward(); opt.step()
    with torch.no_grad():
        p = net(torch.tensor(X[te])).argmax(1).numpy()
    y = A[te]
    print(f"{name}: held-out agreement {np.mean(p==y):.3f} (speed {np.mean(p//3==y//3):.3f}, curvature {np.mean(p%3==y%3):.3f})")
