"""A B timing of the frame networks' input scaling (``qnet._FrameQNetwork.scaled_features``): old
(``fold=False``: frames to float32, divided by 255, then the convolutions) against new (``fold=True``:
frames cast once to the compute dtype, 1/255 folded into the first convolution's weights), in the learner's update
(Double DQN: online pass with grad, online and target passes over next_obs, Huber loss, Adam), on
one network and device, alternating A B A B. ``fold_ab-h100.jsonl`` beside it: this script at revision
ee0373a (where forward always folded, and A was the same code as ``fold=False`` here) on an H100; so forward
folds on the CPU only.

    python fold_ab.py [--device cuda] [--batches 32,128] [--rounds 3] [--seconds 2]

Room: a study script (docs/results). May import: anything in laneshift, torch.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import json
import time

import torch
import torch.nn.functional as F

from laneshift.qnet import build_q_network


def old_forward(net: torch.nn.Module, obs: torch.Tensor) -> torch.Tensor:
    return net.head(net.scaled_features(obs, fold=False).float())


def new_forward(net: torch.nn.Module, obs: torch.Tensor) -> torch.Tensor:
    return net.head(net.scaled_features(obs, fold=True).float())


def updates_per_s(forward, net, target, opt, batch, seconds: float, device: torch.device) -> float:
    obs, next_obs, action, reward = batch

    def step() -> None:
        q = forward(net, obs).gather(1, action[:, None]).squeeze(1)
        with torch.no_grad():
            best = forward(net, next_obs).argmax(1, keepdim=True)
            td = reward + 0.99 * forward(target, next_obs).gather(1, best).squeeze(1)
        loss = F.huber_loss(q, td)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    for _ in range(5):
        step()
    sync()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        step()
        n += 1
    sync()
    return n / (time.perf_counter() - t0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--batches", default="32,128")
    p.add_argument("--precisions", default="fp32,bf16")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--seconds", type=float, default=2.0)
    p.add_argument("--threads", type=int, default=1, help="torch threads on the CPU (the learner's default: 1)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    out = []
    for precision in args.precisions.split(","):
        for b in (int(x) for x in args.batches.split(",")):
            torch.manual_seed(0)
            net = build_q_network((4, 100, 100), 9, cnn="small", conv_precision=precision).to(device)
            target = copy.deepcopy(net).requires_grad_(False)
            opt = torch.optim.Adam(net.parameters(), lr=1e-4)
            g = torch.Generator().manual_seed(1)
            batch = (torch.randint(0, 256, (b, 4, 100, 100), dtype=torch.uint8, generator=g).to(device),
                     torch.randint(0, 256, (b, 4, 100, 100), dtype=torch.uint8, generator=g).to(device),
                     torch.randint(0, 9, (b,), generator=g).to(device), torch.randn(b, generator=g).to(device))
            rates: dict[str, list[float]] = {"old": [], "new": []}
            for _ in range(args.rounds):
                for name, fwd in (("old", old_forward), ("new", new_forward)):
                    rates[name].append(updates_per_s(fwd, net, target, opt, batch, args.seconds, device))
            row = {"precision": precision, "batch": b, **{k: [round(x, 1) for x in v] for k, v in rates.items()},
                   "new_over_old": round(sum(rates["new"]) / sum(rates["old"]), 3)}
            print(json.dumps(row), flush=True)
            out.append(row)
    name = torch.cuda.get_device_name(0) if device.type == "cuda" else "cpu"
    print(json.dumps({"device": name, "torch": torch.__version__, "threads": args.threads, "rounds": args.rounds,
                      "seconds": args.seconds}))
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        raise SystemExit(main())
