"""Offline imitation probe 2: the pixel classifier's held-out accuracy at the learner's own step
sizes and with DrQ's shift, batch 32 (what the pixel runs use).

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch, gymnasium.
"""
import sys, time
import numpy as np, torch, torch.nn.functional as F
import gymnasium as gym
import laneshift.actors  # registers the envs
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.qnet import build_q_network
from laneshift.learner.augment import random_shift

torch.set_num_threads(1)
EPISODES, STEPS, FIT = 60, 300, int(sys.argv[1]) if len(sys.argv) > 1 else 3000
env = gym.make("laneshift/StraightLaneChange-v0", observation="grayscale", max_steps=STEPS)
frames, actions, eps = [], [], []
for ep in range(EPISODES):
    obs, _ = env.reset(seed=10_000 + ep)
    driver = ScriptedDriver(env)
    for _ in range(STEPS):
        a = driver(obs); frames.append(obs); actions.append(a); eps.append(ep)
        obs, r, term, trunc, _ = env.step(a)
        if term or trunc:
            break
x, y, eps = np.stack(frames), np.array(actions), np.array(eps)
train = eps < 48
xt, yt, xv, yv = x[train], y[train], x[~train], y[~train]
for lr, shift in ((1e-4, False), (5e-4, False), (1e-4, True), (5e-4, True)):
    torch.manual_seed(0); g = np.random.default_rng(0); gen = torch.Generator().manual_seed(1)
    net = build_q_network(x.shape[1:], 9, cnn="small", dueling=True, conv_precision="bf16")
    opt = torch.optim.Adam(net.parameters(), lr)
    t = time.time()
    for i in range(FIT):
        idx = g.integers(0, len(xt), 32)
        xb = torch.as_tensor(xt[idx])
        if shift:
            xb = random_shift(xb, 4, gen)
        loss = F.cross_entropy(net(xb), torch.as_tensor(yt[idx]))
        opt.zero_grad(); loss.backward(); opt.step()
    with torch.no_grad():
        acc = lambda xs, ys: float((torch.cat([net(torch.as_tensor(xs[i:i + 256])).argmax(1) for i in range(0, len(xs), 256)]).numpy() == ys).mean())
        print(f"lr {lr:g} shift {shift}: {FIT} updates of 32, train acc {acc(xt[:3000], yt[:3000]):.3f}, held-out {acc(xv, yv):.3f} ({time.time() - t:.0f} s)", flush=True)
