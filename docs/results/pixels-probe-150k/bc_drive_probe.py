"""Offline imitation probe: does a classifier of the scripted driver's actions drive?
Trains SmallCNN (dueling head, bf16 convolutions) on the frames, or a 256x256 MLP on the vector
observation (4th argument "vector"), by cross-entropy on the driver's actions, then
drives it greedily on validation episodes (seeds from 200,000; never the test episodes).

    python bc_drive_probe.py DEMO_EPISODES UPDATES VALIDATION_EPISODES [grayscale|vector]

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch, gymnasium.
"""
import sys, time
import numpy as np, torch, torch.nn.functional as F
import gymnasium as gym
import laneshift.actors  # registers the envs
from laneshift.actors.envs.demonstrator import ScriptedDriver
from laneshift.qnet import build_q_network

torch.set_num_threads(1)
EPISODES, FIT, VAL = (int(a) for a in sys.argv[1:4])
OBS = sys.argv[4] if len(sys.argv) > 4 else "grayscale"
env = gym.make("laneshift/StraightLaneChange-v0", observation=OBS, max_steps=300)
frames, actions = [], []
t = time.time()
for ep in range(EPISODES):
    obs, _ = env.reset(seed=10_000 + ep)
    driver = ScriptedDriver(env)
    for _ in range(300):
        a = driver(obs); frames.append(obs); actions.append(a)
        obs, r, term, trunc, _ = env.step(a)
        if term or trunc:
            break
x, y = np.stack(frames).astype(np.float32) if OBS == "vector" else np.stack(frames), np.array(actions)
print(f"{len(y)} demo states from {EPISODES} episodes ({time.time() - t:.0f} s)", flush=True)
torch.manual_seed(0); g = np.random.default_rng(0)
net = build_q_network(x.shape[1:], 9, (256, 256), dueling=True, cnn="small", conv_precision="bf16")
opt = torch.optim.Adam(net.parameters(), 1e-4)
t = time.time()
for i in range(FIT):
    idx = g.integers(0, len(y), 32)
    loss = F.cross_entropy(net(torch.as_tensor(x[idx])), torch.as_tensor(y[idx]))
    opt.zero_grad(); loss.backward(); opt.step()
print(f"fit {FIT} updates in {time.time() - t:.0f} s, last loss {loss.item():.3f}", flush=True)
env = gym.make("laneshift/StraightLaneChange-v0", observation=OBS, max_steps=300, initial_lane="random")
survived = achieved = 0
with torch.no_grad():
    for k in range(VAL):
        obs, _ = env.reset(seed=200_000 + k)
        crashed = False
        for _ in range(300):
            obs, r, term, trunc, info = env.step(int(net(torch.as_tensor(np.asarray(obs[None], dtype=x.dtype))).argmax(1)))
            if term:
                crashed = True
            if term or trunc:
                break
        survived += not crashed
        achieved += (not crashed) and bool(info["on_target_lane"])
print(f"greedy on {VAL} validation episodes (random lane): survival {survived / VAL:.3f}, achievement {achieved / VAL:.3f}", flush=True)
