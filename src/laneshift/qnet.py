"""The Q-network and its weights codec: the part of the contract that actors, the learner and
evaluation share (contract floor: imports torch, numpy, safetensors-format helpers from
``laneshift.wire``; never a component).

Q-networks: an MLP for vector observations, the Nature CNN or a small CNN for stacked grayscale frames,
each with a plain or a dueling head (Wang et al. 2016: Q = V + A - mean A); an MLP may have one
head per road (``heads``: the allroads observation ends with the road's one-hot, which picks it).

    >>> net = build_q_network((25,), 9, hidden=(64, 64))
    >>> tuple(net(torch.zeros(2, 25)).shape)
    (2, 9)
    >>> tuple(build_q_network((25,), 9, hidden=(64,), dueling=True)(torch.zeros(2, 25)).shape)
    (2, 9)
    >>> tuple(build_q_network((25,), 9, hidden=(64,), dueling=True, heads=4)(torch.zeros(2, 25)).shape)
    (2, 9)

Why dueling here: at 10 decisions per second one action changes little of a 10-second return,
so the Q-values of the 9 actions differ by a tiny fraction of their size. A separate value
stream lets the advantage head spend its capacity on those small differences; pre-trained on
the scripted demos it chose the demonstrator's action more often and survived more
(docs/results-history.md, round 2).

Weights travel and rest as safetensors (``wire.encode_weights`` with a version; checkpoints are
plain safetensors files that ``safetensors.torch.load_file`` reads): ``weights_of`` (the typed
value), ``to_wire`` (its message), ``load_into`` (strict names and shapes), ``save_checkpoint``
(atomic), ``load_checkpoint``.

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from laneshift import wire
from laneshift.config.checks import row_window
from laneshift.wire import tensors_digest  # noqa: F401 - re-exported: a checkpoint's identity

class DuelingHead(nn.Module):
    """Q(s, a) = V(s) + A(s, a) - mean_a A(s, a) from a feature vector; with ``heads`` > 1, one V and
    one A per head, computed together ((batch, heads, actions)), the caller picking a head per row."""

    def __init__(self, features: int, n_actions: int, heads: int = 1):
        super().__init__()
        self.heads, self.n_actions = heads, n_actions
        self.value = nn.Linear(features, heads)
        self.advantage = nn.Linear(features, heads * n_actions)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if self.heads == 1:
            adv = self.advantage(h)
            return self.value(h) + adv - adv.mean(dim=1, keepdim=True)
        adv = self.advantage(h).view(-1, self.heads, self.n_actions)
        return self.value(h).unsqueeze(2) + adv - adv.mean(dim=2, keepdim=True)


def _head(features: int, n_actions: int, dueling: bool, heads: int = 1) -> nn.Module:
    return DuelingHead(features, n_actions, heads) if dueling else nn.Linear(features, heads * n_actions)


def select_head(q_heads: torch.Tensor, onehot: torch.Tensor) -> torch.Tensor:
    """Each row's Q-values from the head its one-hot names: (batch, heads, actions) -> (batch, actions).
    A weighted sum rather than an index, so it runs as one batched op and is exact for a one-hot."""
    return (q_heads * onehot.unsqueeze(2)).sum(dim=1)


class MLPQNetwork(nn.Module):
    """Linear + ReLU layers and a head. ``heads`` > 1: one head per value of the one-hot that ends the
    observation (allroads: the road, so each road has its own Q head on a shared trunk); the layers'
    state-dict names stay those of one head (``net.<i>.weight``, a dueling head's ``value`` and
    ``advantage``), only the head's rows multiply."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: tuple[int, ...] = (256, 256), dueling: bool = False,
                 heads: int = 1):
        super().__init__()
        if not 1 <= heads < obs_dim:
            raise ValueError(f"heads must be in [1, {obs_dim}) (a one-hot ends the observation), got {heads}")
        layers: list[nn.Module] = []
        size = obs_dim
        for h in hidden:
            layers += [nn.Linear(size, h), nn.ReLU()]
            size = h
        layers.append(_head(size, n_actions, dueling, heads))
        self.net = nn.Sequential(*layers)
        self.heads, self.n_actions = heads, n_actions
        # The hidden layers' compute dtype (``build_q_network``'s mlp_precision): None runs them in
        # float32; bfloat16 runs them under autocast. As with the convolutions, the parameters stay
        # float32 and the head runs in float32, so the Q-values keep float32's resolution.
        self.trunk_dtype: torch.dtype | None = None

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs.float()
        if self.trunk_dtype is None:
            out = self.net(x)
        else:
            h = x
            with torch.autocast(x.device.type, dtype=self.trunk_dtype):
                for layer in list(self.net)[:-1]:  # the hidden layers (the head is last)
                    h = layer(h)
            out = self.net[-1](h.float())
        if self.heads == 1:
            return out
        return select_head(out.view(-1, self.heads, self.n_actions), x[:, -self.heads:])


class _FrameQNetwork(nn.Module):
    """Convolutions over uint8 frames (C, H, W), scaled to [0, 1] inside, then one hidden layer
    of ``units`` and the head. Subclasses give the convolutions."""

    def __init__(self, features: nn.Sequential, in_shape: tuple[int, int, int], units: int, n_actions: int,
                 dueling: bool, rows: tuple[int, int] | None = None):
        super().__init__()
        if not isinstance(features[0], nn.Conv2d):
            raise TypeError("the features must start with a Conv2d (forward folds the 1/255 scale into it)")
        self.features = features
        # The frames' rows the convolutions see (learner.cnn_rows; None: all): a slice, so the
        # rows outside cost neither the cast nor the convolutions.
        self.rows = rows
        if rows is not None:
            in_shape = (in_shape[0], rows[1] - rows[0], in_shape[2])
        try:
            with torch.no_grad():
                flat = self.features(torch.zeros(1, *in_shape)).shape[1]
        except RuntimeError:  # a kernel larger than the (windowed) frame
            raise ValueError(f"{type(self).__name__}: frames of {in_shape[1]} x {in_shape[2]} are too small for its "
                             "convolutions") from None
        self.head = nn.Sequential(nn.Linear(flat, units), nn.ReLU(), _head(units, n_actions, dueling))
        # The convolutions' compute dtype (``build_q_network``'s conv_precision): None runs them in
        # float32; bfloat16 runs them under autocast. The parameters stay float32 either way (the
        # weights on the wire do not change) and the layers after the convolutions always run in
        # float32, so Q-values keep float32's resolution where actions differ by small margins.
        self.conv_dtype: torch.dtype | None = None

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.scaled_features(obs, fold=obs.device.type == "cpu").float())

    def trunk(self, obs: torch.Tensor) -> torch.Tensor:
        """Every layer but the Q output layer (``head[-1]``): ``forward(obs) == output(trunk(obs))``."""
        return self.head[:-1](self.scaled_features(obs, fold=obs.device.type == "cpu").float())

    def output(self, h: torch.Tensor) -> torch.Tensor:
        """The Q output layer (the dueling head or the plain linear one) on ``trunk``'s output."""
        return self.head[-1](h)

    def scaled_features(self, obs: torch.Tensor, fold: bool) -> torch.Tensor:
        """The convolutions' output for raw frames (0-255), computed as the layers over frames / 255.

        ``fold`` (what forward uses on the CPU): conv(frames / 255) computed as conv(frames) with the
        first layer's weights / 255, the frames cast once to the compute dtype (0..255 are exact in
        bfloat16 too) instead of a float32 pass and a division, which took about 40 % of SmallCNN's
        bf16 update at batch 32 on one CPU thread (torch.profiler); the update ran 1.10x (float32) and
        1.22x (bf16) as fast (docs/results/pixels-gpu/fold_ab.py, A B A B). Not on CUDA: there the fold
        made the update 0.83-0.92x in float32 on an H100 (docs/results/pixels-gpu/fold_ab-h100.jsonl).
        """
        if self.rows is not None:
            obs = obs[:, :, self.rows[0]:self.rows[1]]
        autocast = (contextlib.nullcontext() if self.conv_dtype is None
                    else torch.autocast(obs.device.type, dtype=self.conv_dtype))
        if not fold:
            with autocast:
                return self.features(obs.float() / 255.0)
        dtype = self.conv_dtype or torch.float32
        first, rest = self.features[0], self.features[1:]
        with autocast:
            h = F.conv2d(obs.to(dtype), (first.weight * (1.0 / 255.0)).to(dtype), first.bias.to(dtype),
                         first.stride, first.padding)
            return rest(h)


class NatureCNN(_FrameQNetwork):
    """Mnih et al. 2015."""

    def __init__(self, in_shape: tuple[int, int, int], n_actions: int, dueling: bool = False,
                 rows: tuple[int, int] | None = None):
        super().__init__(nn.Sequential(
            nn.Conv2d(in_shape[0], 32, 8, stride=4), nn.ReLU(),
            nn.Conv2d(32, 64, 4, stride=2), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1), nn.ReLU(), nn.Flatten()), in_shape, 512, n_actions, dueling, rows)


class SmallCNN(_FrameQNetwork):
    """A pixel learner for 2 CPU cores: Nature's first two convolutions at half the channels, no
    third, a 256-unit layer (1.0 M parameters vs 2.7 M). On this 2-core machine it updates about
    3x as fast as NatureCNN on 4 x 100 x 100 frames (`laneshift bench learner`, cases small-b32 and
    small-b64), which is what makes hours-long pixel runs possible without a GPU."""

    def __init__(self, in_shape: tuple[int, int, int], n_actions: int, dueling: bool = False,
                 rows: tuple[int, int] | None = None):
        super().__init__(nn.Sequential(
            nn.Conv2d(in_shape[0], 16, 8, stride=4), nn.ReLU(),
            nn.Conv2d(16, 32, 4, stride=2), nn.ReLU(), nn.Flatten()), in_shape, 256, n_actions, dueling, rows)


CNNS = {"nature": NatureCNN, "small": SmallCNN}

#: The convolutions' (or an MLP's hidden layers') compute dtype per ``learner.cnn_precision``
#: (``learner.mlp_precision``).
COMPUTE_DTYPES: dict[str, torch.dtype | None] = {"fp32": None, "bf16": torch.bfloat16}


def _compute_dtype(precision: str, what: str) -> torch.dtype | None:
    """``precision``'s autocast dtype (None: float32); ``what`` names the layers in the error."""
    if precision not in COMPUTE_DTYPES:
        raise ValueError(f"no {what} precision {precision!r} (one of {', '.join(COMPUTE_DTYPES)})")
    return COMPUTE_DTYPES[precision]


def _cnn_spec(cnn: str, obs_shape: tuple[int, ...]) -> tuple[str, tuple[int, int] | None]:
    """``"small"`` or ``"small[26:74]"`` (learner.network_cnn) -> the CNN's name and its row window,
    checked against the frames' height."""
    name, _, window = cnn.partition("[")
    if name not in CNNS:
        raise ValueError(f"no CNN {name!r} (one of {', '.join(CNNS)})")
    if not window:
        return name, None
    rows = row_window(window.rstrip("]")) if window.endswith("]") else None
    if rows is None or rows[1] > obs_shape[1]:
        raise ValueError(f"CNN {cnn!r}: the rows must be [FIRST:END] with 0 <= FIRST < END <= {obs_shape[1]} "
                         "(the frames' height)")
    return name, rows


def build_q_network(obs_shape: tuple[int, ...], n_actions: int, hidden: tuple[int, ...] = (256, 256),
                    dueling: bool = False, cnn: str = "nature", conv_precision: str = "fp32",
                    heads: int = 1, mlp_precision: str = "fp32") -> nn.Module:
    """MLP for 1-D observations, its hidden layers computed in ``mlp_precision``; for (stack, H, W)
    images the Nature CNN or the small CNN (``cnn``), its convolutions computed in ``conv_precision``
    (fp32 or bf16 each; the head always in fp32). ``heads`` > 1 (an MLP only): one Q head per value
    of the one-hot that ends the observation."""
    if len(obs_shape) == 1:
        trunk_dtype = _compute_dtype(mlp_precision, "MLP")
        mlp = MLPQNetwork(obs_shape[0], n_actions, hidden, dueling, heads)
        mlp.trunk_dtype = trunk_dtype
        return mlp
    if heads != 1:
        raise ValueError(f"heads: one Q head per road needs a vector observation (its one-hot), got {obs_shape}")
    if len(obs_shape) == 3:
        name, rows = _cnn_spec(cnn, obs_shape)
        conv_dtype = _compute_dtype(conv_precision, "conv")
        net = CNNS[name](tuple(obs_shape), n_actions, dueling, rows)  # type: ignore[arg-type]
        net.conv_dtype = conv_dtype
        return net
    raise ValueError(f"no Q-network for observation shape {obs_shape}")


# ------------------------------------------------------------------ weights

def weights_of(net: nn.Module, version: int, phase: int, updates: int) -> wire.Weights:
    """``net``'s weights as the typed value the learner publishes. On the CPU the arrays share
    memory with the network: encode (or copy) them before its next update."""
    tensors = {k: v.detach().cpu().numpy() for k, v in net.state_dict().items()}
    return wire.Weights(version=version, phase=phase, updates=updates, tensors=tensors)


def to_wire(net: nn.Module, version: int, phase: int, updates: int) -> bytes:
    """``weights_of`` as a WEIGHTS message."""
    return wire.encode_weights(weights_of(net, version, phase, updates))


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
