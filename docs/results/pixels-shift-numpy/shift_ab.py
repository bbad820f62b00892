"""The DrQ shift (learner/augment.py's random_shift) in torch against numpy, A B A B on 32 rows of
4 x 100 x 100 uint8 frames, torch on 2 threads as the learner runs it; the two must give the same
pixels. Run it beside a training run to see what the learner sees when another process shares its
cores, and on a quiet machine for the baseline.

Room: docs (a study's script). May import: laneshift (any floor), numpy, torch, the standard library.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from laneshift.learner.augment import random_shift


def shift_numpy(frames: torch.Tensor, pad: int, generator: torch.Generator) -> torch.Tensor:
    """learner/augment.py's random_shift with its pad and crops in numpy (no threads): the same
    offsets from the same generator, so the same pixels."""
    height, width = frames.shape[2:]
    corners = (torch.randint(-pad, pad + 1, (2, frames.shape[0]), generator=generator) + pad).tolist()
    padded = np.pad(frames.numpy(), ((0, 0), (0, 0), (pad, pad), (pad, pad)), mode="edge")
    out = np.empty(frames.shape, dtype=padded.dtype)
    for row, (top, left) in enumerate(zip(*corners)):
        out[row] = padded[row, :, top:top + height, left:left + width]
    return torch.from_numpy(out)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=4)
    p.add_argument("--calls", type=int, default=200)
    p.add_argument("--label", default="", help="a word for the conditions (quiet, beside-run)")
    args = p.parse_args()
    torch.set_num_threads(2)
    frames = torch.randint(0, 256, (32, 4, 100, 100), dtype=torch.uint8, generator=torch.Generator().manual_seed(0))
    assert torch.equal(random_shift(frames, 4, torch.Generator().manual_seed(1)),
                       shift_numpy(frames, 4, torch.Generator().manual_seed(1)))
    gen = torch.Generator().manual_seed(2)
    for rnd in range(args.rounds):
        for name, shift in (("torch", random_shift), ("numpy", shift_numpy)):
            t = time.perf_counter()
            for _ in range(args.calls):
                shift(frames, 4, gen)
            ms = (time.perf_counter() - t) / args.calls * 1e3
            print(json.dumps({"label": args.label, "round": rnd, "path": name, "ms_per_call": round(ms, 3)}), flush=True)


if __name__ == "__main__":
    main()
