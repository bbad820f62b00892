"""How well can a plain supervised classifier imitate the scripted driver on merge? A diagnostic of
docs/RESULTS.md (merge), not part of the product: trains an MLP with cross-entropy on one demo shard
and reports its agreement with the driver on the held-out episodes of a larger shard.

    python imitation_probe.py TRAIN_SHARD HELDOUT_SHARD [HIDDEN=256,256] [EPOCHS=20] [FIRST_HELDOUT_EPISODE=600]

Room: a diagnostic script beside its results (run by path, not installed). May import: laneshift
(any floor), numpy, torch.
"""
import sys, time, numpy as np, torch
from laneshift.demos.shard import load_shard
torch.set_num_threads(1)
train = load_shard(sys.argv[1])
big = load_shard(sys.argv[2])
hidden = [int(h) for h in sys.argv[3].split(",")] if len(sys.argv) > 3 else [256, 256]
epochs = int(sys.argv[4]) if len(sys.argv) > 4 else 20
held = big.episode_ids >= (int(sys.argv[5]) if len(sys.argv) > 5 else 600)
X = torch.tensor(train.observations); Y = torch.tensor(train.actions)
Xh = torch.tensor(big.observations[held]); Yh = torch.tensor(big.actions[held])
layers, d = [], X.shape[1]
for h in hidden: layers += [torch.nn.Linear(d, h), torch.nn.ReLU()]; d = h
net = torch.nn.Sequential(*layers, torch.nn.Linear(d, 9))
opt = torch.optim.Adam(net.parameters(), 1e-3)
t0 = time.time()
for ep in range(epochs):
    perm = torch.randperm(len(X))
    for i in range(0, len(X), 256):
        idx = perm[i:i+256]
        loss = torch.nn.functional.cross_entropy(net(X[idx]), Y[idx])
        opt.zero_grad(); loss.backward(); opt.step()
    with torch.no_grad():
        a = (net(X).argmax(1) == Y).float().mean().item(); p = net(Xh).argmax(1)
        ah = (p == Yh).float().mean().item(); cs = ((p % 3) == (Yh % 3)).float().mean().item(); sp = ((p // 3) == (Yh // 3)).float().mean().item()
    print(f"epoch {ep} train-acc {a:.3f} held-acc {ah:.3f} (speed {sp:.3f} curv {cs:.3f}) {time.time()-t0:.0f}s", flush=True)
