"""Offline imitation probe for the pixel observation: can a SmallCNN tell the scripted driver's
action from the frames, and does a wider view help? Records the driver on the straight road with
the grayscale observation at two scales (2 px/m: 50 m view, the env's default; 1 px/m: 100 m) and
the vector observation of the same states, trains a classifier on 80 % of the episodes, reports
held-out accuracy.

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch, gymnasium.
"""
import sys, time
import numpy as np, torch, torch.nn as nn, torch.nn.functional as F
import gymnasium as gym
import laneshift.actors  # registers the envs
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.qnet import build_q_network

torch.set_num_threads(1)
EPISODES, STEPS = int(sys.argv[1]) if len(sys.argv) > 1 else 60, 300  # python view_probe.py [EPISODES] [UPDATES]
FIT_STEPS = int(sys.argv[2]) if len(sys.argv) > 2 else 3000


def record(scaling):
    env = gym.make("laneshift/StraightLaneChange-v0", observation="grayscale", scaling=scaling, max_steps=STEPS)
    core = env.unwrapped
    frames, vectors, actions, eps = [], [], [], []
    for ep in range(EPISODES):
        obs, _ = env.reset(seed=10_000 + ep)
        driver = ScriptedDriver(env)
        for _ in range(STEPS):
            a = driver(obs)
            frames.append(obs); vectors.append(core._vector_obs(core.ego)); actions.append(a); eps.append(ep)
            obs, r, term, trunc, _ = env.step(a)
            if term or trunc:
                break
    return np.stack(frames), np.stack(vectors).astype(np.float32), np.array(actions), np.array(eps)


def fit(x, y, eps, net, steps=FIT_STEPS, batch=64, lr=5e-4):
    train = eps < int(EPISODES * 0.8)
    xt, yt, xv, yv = x[train], y[train], x[~train], y[~train]
    opt = torch.optim.Adam(net.parameters(), lr)
    g = np.random.default_rng(0)
    for i in range(steps):
        idx = g.integers(0, len(xt), batch)
        loss = F.cross_entropy(net(torch.as_tensor(xt[idx])), torch.as_tensor(yt[idx]))
        opt.zero_grad(); loss.backward(); opt.step()
    with torch.no_grad():
        pred = torch.cat([net(torch.as_tensor(xv[i:i + 256])).argmax(1) for i in range(0, len(xv), 256)]).numpy()
    return float((pred == yv).mean()), float(np.bincount(yv).max() / len(yv))


for scaling in (2.0, 1.0):
    t = time.time()
    fr, vec, act, eps = record(scaling)
    print(f"scaling {scaling}: {len(act)} states from {EPISODES} episodes in {time.time() - t:.0f} s", flush=True)
    if scaling == 2.0:
        torch.manual_seed(0)
        acc, major = fit(vec, act, eps, build_q_network(vec.shape[1:], 9, (256, 256)))
        print(f"  vector MLP: held-out accuracy {acc:.3f} (majority class {major:.3f})", flush=True)
    torch.manual_seed(0)
    t = time.time()
    acc, major = fit(fr, act, eps, build_q_network(fr.shape[1:], 9, cnn="small", conv_precision="bf16"))
    print(f"  frames SmallCNN (scaling {scaling}): held-out accuracy {acc:.3f} (majority {major:.3f}) in {time.time() - t:.0f} s", flush=True)
