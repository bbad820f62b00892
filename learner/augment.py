"""Image augmentation for the learner's batches: DrQ's random shift (Kostrikov, Yarats and Fergus
2021, "Image Augmentation Is All You Need"), the regulariser that made pixel DQN sample-efficient
on Atari 100k. Each row's stacked frames move together by a random whole-pixel offset of up to
``pad`` pixels in each direction, the border filled by repeating the edge pixels (DrQ pads with
replicate padding and crops back), so a car seen a few pixels away is still the same situation.

Written here rather than taken from a library: torchvision's RandomCrop draws one offset per call,
not per row; this crops the uint8 frames with a fresh offset per row.

Room: learner (component). May import: torch.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def random_shift(frames: torch.Tensor, pad: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``frames`` ([batch, channels, height, width], any dtype) with each row shifted by its own
    random offset in [-pad, pad] along both axes, edges repeated; the same dtype and device.

    DrQ's own form: replicate-pad by ``pad``, then crop the original size at a random corner per
    row. The crops are copied row by row: for 32 rows of 4 x 100 x 100 uint8 frames 0.5-1.7 ms,
    against 4.7-7.8 ms for one advanced-indexing gather over the whole batch (measured on the
    2-core dev machine beside a training run).
    """
    if frames.dim() != 4:
        raise ValueError(f"random_shift: expected [batch, channels, height, width] frames, got shape {tuple(frames.shape)}")
    rows, _, height, width = frames.shape
    padded = F.pad(frames, (pad, pad, pad, pad), mode="replicate")
    corners = (torch.randint(-pad, pad + 1, (2, rows), generator=generator) + pad).tolist()
    out = torch.empty_like(frames)
    for row, (top, left) in enumerate(zip(*corners)):
        out[row] = padded[row, :, top:top + height, left:left + width]
    return out
