"""torch state dicts <-> the wire's Weights (safetensors bytes + version)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from laneshift import wire
from laneshift.wire import tensors_digest  # noqa: F401 - where it used to live


def to_wire(net: nn.Module, version: int, phase: int, updates: int) -> bytes:
    tensors = {k: v.detach().cpu().numpy() for k, v in net.state_dict().items()}
    return wire.encode_weights(wire.Weights(version=version, phase=phase, updates=updates, tensors=tensors))


def load_into(net: nn.Module, tensors: dict[str, np.ndarray]) -> None:
    """Load arrays into ``net``; refuses missing/extra keys or wrong shapes (strict)."""
    state = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in tensors.items()}
    expected = net.state_dict()
    if set(state) != set(expected):
        raise ValueError(f"weights keys {sorted(state)} do not match the network {sorted(expected)}")
    for k, v in state.items():
        if tuple(v.shape) != tuple(expected[k].shape):
            raise ValueError(f"weights {k}: shape {tuple(v.shape)} != {tuple(expected[k].shape)}")
    net.load_state_dict(state)


def save_checkpoint(net: nn.Module, path: str | Path, meta: dict[str, str | int | float]) -> Path:
    """A checkpoint is a plain safetensors file (readable by ``safetensors.torch.load_file``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().numpy() for k, v in net.state_dict().items()}
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(wire.safetensors_dumps(tensors, {k: str(v) for k, v in meta.items()}))
    tmp.replace(path)  # atomic: a crash never leaves a half-written checkpoint
    return path


def load_checkpoint(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    return wire.safetensors_loads(Path(path).read_bytes())
