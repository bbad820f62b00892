"""Behaviour cloning alone on a demo shard: how much of the demonstrator's choice an observation carries.

The network of the runs (SmallCNN with bf16 convolutions and DrQ's 4-pixel shift for frames, the
256 x 256 MLP for vectors; plain head, its 9 outputs as logits) learns the demonstrator's action by
cross-entropy alone, Adam at 1e-4 and batch 32 as the pixel probes' learner; episodes 0-207 of the shard
train, 208-259 are held out (3,000 of their transitions, drawn once). Prints one JSON line per 1,000
updates (held-out cross-entropy and accuracy) and saves the network for ``drive.py``.

    python bc.py SHARD_DIR LABEL --updates 20000 --rows 22:78 --save net.pt

Room: a study script (docs/results). May import: anything in laneshift, torch, numpy.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch
import torch.nn.functional as F

from laneshift.demos.shard import read_verified
from laneshift.learner.augment import random_shift
from laneshift.qnet import build_q_network


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("shard")
    parser.add_argument("label")
    parser.add_argument("--updates", type=int, default=8000)
    parser.add_argument("--rows", default="", help="learner.cnn_rows for frames (FIRST:END; default the whole frame)")
    parser.add_argument("--lr", type=float, default=1e-4)
    parser.add_argument("--save", default="", help="where to save the network (for drive.py)")
    parser.add_argument("--save-at", default="", help="also save at these update counts (comma-separated), "
                        "as SAVE with -<updates> before its suffix")
    parser.add_argument("--seed", type=int, default=0, help="the network's initialisation, the batches and the shifts")
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)

    raw = read_verified(args.shard)
    obs, acts = raw.observations, raw.actions
    rng = np.random.default_rng(args.seed)

    def index(episodes: range) -> np.ndarray:
        return np.array([(e, t) for e in episodes for t in range(len(acts[e]))])

    train, held_out = index(range(208)), index(range(208, len(acts)))
    held_out = held_out[np.random.default_rng(0).choice(len(held_out), 3000, replace=False)]  # whatever the seed
    shape = obs[0].shape[1:]
    image = len(shape) == 3
    cnn = f"small[{args.rows}]" if args.rows else "small"
    net = build_q_network(shape, 9, cnn=cnn, conv_precision="bf16" if image else "fp32")
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)

    def batch(idx: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        o = np.stack([obs[e][t] for e, t in idx])
        return torch.from_numpy(o), torch.from_numpy(np.array([acts[e][t] for e, t in idx])).long()

    test_obs, test_act = batch(held_out)

    def evaluate() -> tuple[float, float]:
        net.eval()
        ce = acc = 0.0
        with torch.no_grad():
            for i in range(0, len(held_out), 500):
                logits = net(test_obs[i:i + 500])
                ce += F.cross_entropy(logits, test_act[i:i + 500], reduction="sum").item()
                acc += (logits.argmax(1) == test_act[i:i + 500]).sum().item()
        net.train()
        return ce / len(held_out), acc / len(held_out)

    tail = np.concatenate([acts[e] for e in range(208, len(acts))])
    p = np.bincount(tail, minlength=9) / len(tail)
    entropy = float(-(p[p > 0] * np.log(p[p > 0])).sum())
    print(json.dumps({"label": args.label, "marginal_entropy": entropy}), flush=True)
    save_at = {int(u) for u in args.save_at.split(",") if u}
    start = time.time()
    for update in range(1, args.updates + 1):
        o, a = batch(train[rng.integers(0, len(train), 32)])
        if image:
            o = random_shift(o, 4)
        loss = F.cross_entropy(net(o), a)
        opt.zero_grad()
        loss.backward()
        opt.step()
        if update % 1000 == 0:
            ce, acc = evaluate()
            print(json.dumps({"label": args.label, "updates": update, "heldout_ce": round(ce, 4),
                              "heldout_acc": round(acc, 4), "train_ce_last": round(loss.item(), 4),
                              "s": round(time.time() - start, 1)}), flush=True)
        if args.save and update in save_at:
            stem, dot, suffix = args.save.rpartition(".")
            torch.save({"state": net.state_dict(), "shape": shape, "cnn": cnn},
                       f"{stem}-{update}.{suffix}" if dot else f"{args.save}-{update}")
    if args.save:
        torch.save({"state": net.state_dict(), "shape": shape, "cnn": cnn}, args.save)


if __name__ == "__main__":
    main()
