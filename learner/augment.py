"""Image augmentation for the learner's batches: DrQ's random shift (Kostrikov, Yarats and Fergus
2021, "Image Augmentation Is All You Need"), the regulariser that made pixel DQN sample-efficient
on Atari 100k. Each row's stacked frames move together by a random whole-pixel offset of up to
``pad`` pixels in each direction, the border filled by repeating the edge pixels (DrQ pads with
replicate padding and crops back), so a car seen a few pixels away is still the same situation.

Written here rather than taken from a library: torchvision's RandomCrop draws one offset per call,
not per row; this crops the uint8 frames with a fresh offset per row.

Room: learner (component). May import: numpy, torch.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def random_shift(frames: torch.Tensor, pad: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``frames`` ([batch, channels, height, width], any dtype) with each row shifted by its own
    random offset in [-pad, pad] along both axes, edges repeated; the same dtype and device.

    DrQ's own form: replicate-pad by ``pad``, then crop the original size at a random corner per
    row. On the CPU the pad and the crops run in numpy: each torch copy of a 40 kB crop is split
    over the OpenMP threads, and with another process on the cores (the replay server beside the
    learner) the threads wait for each other's time slices: in py-spy 40 % of a pixel run's update
    thread sat in these copies (docs/results/pixels-shift-numpy/). The same offsets, the same output.
    """
    if frames.dim() != 4:
        raise ValueError(f"random_shift: expected [batch, channels, height, width] frames, got shape {tuple(frames.shape)}")
    rows = frames.shape[0]
    corners = (torch.randint(-pad, pad + 1, (2, rows), generator=generator) + pad).tolist()
    on_numpy = frames.device.type == "cpu" and frames.dtype != torch.bfloat16 and not frames.requires_grad
    return (_crops_numpy if on_numpy else _crops_torch)(frames, pad, list(zip(*corners)))


def _crops_numpy(frames: torch.Tensor, pad: int, corners: list[tuple[int, int]]) -> torch.Tensor:
    """The crops at ``corners`` (top, left in the padded frame) of the edge-padded CPU ``frames``, in numpy."""
    height, width = frames.shape[2:]
    padded = np.pad(frames.numpy(), ((0, 0), (0, 0), (pad, pad), (pad, pad)), mode="edge")
    out = np.empty(frames.shape, dtype=padded.dtype)
    for row, (top, left) in enumerate(corners):
        out[row] = padded[row, :, top:top + height, left:left + width]
    return torch.from_numpy(out)


def _crops_torch(frames: torch.Tensor, pad: int, corners: list[tuple[int, int]]) -> torch.Tensor:
    """The same crops in torch, on the frames' device (a GPU's, or bfloat16 frames numpy cannot hold)."""
    height, width = frames.shape[2:]
    padded = F.pad(frames, (pad, pad, pad, pad), mode="replicate")
    out = torch.empty_like(frames)
    for row, (top, left) in enumerate(corners):
        out[row] = padded[row, :, top:top + height, left:left + width]
    return out
