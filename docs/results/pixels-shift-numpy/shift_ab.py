"""The DrQ shift's crops (learner/augment.py) in torch against numpy, A B A B on 32 rows of
4 x 100 x 100 uint8 frames, torch on 2 threads as the learner runs it; the two must give the same
pixels. Run it beside a training run to see what the learner sees when another process shares its
cores, and on a quiet machine for the baseline.

Room: docs (a study's script). May import: numpy, torch, the standard library.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch
import torch.nn.functional as F


def _crops_torch(frames: torch.Tensor, pad: int, corners: list[tuple[int, int]]) -> torch.Tensor:
    """learner/augment.py's crops: replicate-pad, then one copy per row."""
    height, width = frames.shape[2:]
    padded = F.pad(frames, (pad, pad, pad, pad), mode="replicate")
    out = torch.empty_like(frames)
    for row, (top, left) in enumerate(corners):
        out[row] = padded[row, :, top:top + height, left:left + width]
    return out


def _crops_numpy(frames: torch.Tensor, pad: int, corners: list[tuple[int, int]]) -> torch.Tensor:
    """The same crops in numpy (no threads)."""
    height, width = frames.shape[2:]
    padded = np.pad(frames.numpy(), ((0, 0), (0, 0), (pad, pad), (pad, pad)), mode="edge")
    out = np.empty(frames.shape, dtype=padded.dtype)
    for row, (top, left) in enumerate(corners):
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
    gen = torch.Generator().manual_seed(1)
    draw = lambda: list(zip(*(torch.randint(0, 9, (2, 32), generator=gen)).tolist()))  # noqa: E731
    corners = draw()
    assert torch.equal(_crops_numpy(frames, 4, corners), _crops_torch(frames, 4, corners))
    for rnd in range(args.rounds):
        for name, crops in (("torch", _crops_torch), ("numpy", _crops_numpy)):
            t = time.perf_counter()
            for _ in range(args.calls):
                crops(frames, 4, draw())
            ms = (time.perf_counter() - t) / args.calls * 1e3
            print(json.dumps({"label": args.label, "round": rnd, "path": name, "ms_per_call": round(ms, 3)}), flush=True)


if __name__ == "__main__":
    main()
