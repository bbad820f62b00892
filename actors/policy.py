"""The env worker's copy of the Q-network, acting epsilon-greedily.

For vector observations the MLP runs in numpy: an env worker then never imports torch (about
180 MB of RSS per worker process, measured with `laneshift bench run`), and a forward pass of a
few rows is faster than torch's per-call overhead. It reads the learner's weights by their
state-dict names (``net.0.weight``, ..., a dueling head's ``value`` / ``advantage``) and computes
exactly what ``laneshift.qnet.MLPQNetwork`` computes, in float32, one head per road included. Image observations use the
torch network (the Nature CNN), imported only then.
Room: actors, the env-running component. May import: the contract (``laneshift.wire``), numpy, threadpoolctl; torch and
``laneshift.qnet`` only for image observations.

    >>> import numpy as np
    >>> p = QPolicy((4,), 3, hidden=(8,), seed=0)
    >>> p.act(np.zeros((2, 4), np.float32), epsilon=0.0).shape
    (2,)
"""

from __future__ import annotations

import numpy as np

from laneshift import wire


class NumpyMLP:
    """``MLPQNetwork``'s forward pass (Linear, ReLU, ..., plain or dueling head) in numpy."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: tuple[int, ...], dueling: bool, heads: int = 1):
        if not 1 <= heads < obs_dim:
            raise ValueError(f"heads must be in [1, {obs_dim}) (a one-hot ends the observation), got {heads}")
        self.shapes: dict[str, tuple[int, ...]] = {}
        size, index = obs_dim, 0
        for h in hidden:
            self.shapes[f"net.{index}.weight"], self.shapes[f"net.{index}.bias"] = (h, size), (h,)
            size, index = h, index + 2  # each hidden Linear is followed by a ReLU in the Sequential
        head = f"net.{index}"
        if dueling:
            self.shapes.update({f"{head}.value.weight": (heads, size), f"{head}.value.bias": (heads,),
                                f"{head}.advantage.weight": (heads * n_actions, size),
                                f"{head}.advantage.bias": (heads * n_actions,)})
        else:
            self.shapes.update({f"{head}.weight": (heads * n_actions, size), f"{head}.bias": (heads * n_actions,)})
        self.hidden_layers, self.head, self.dueling = len(hidden), head, dueling
        self.heads, self.n_actions = heads, n_actions
        # Zero weights until the learner's first version arrives (workers wait for it before acting).
        self.load({k: np.zeros(s, np.float32) for k, s in self.shapes.items()})

    def load(self, tensors: dict[str, np.ndarray]) -> None:
        """Strict, like ``laneshift.qnet.load_into``: the same names and shapes, or ValueError."""
        if set(tensors) != set(self.shapes):
            raise ValueError(f"weights keys {sorted(tensors)} do not match the network {sorted(self.shapes)}")
        for k, v in tensors.items():
            if tuple(v.shape) != self.shapes[k]:
                raise ValueError(f"weights {k}: shape {tuple(v.shape)} != {self.shapes[k]}")
        t = {k: np.ascontiguousarray(v, np.float32) for k, v in tensors.items()}
        # Transposed once here, so each forward pass is x @ W + b.
        self.layers = [(t[f"net.{2 * i}.weight"].T.copy(), t[f"net.{2 * i}.bias"]) for i in range(self.hidden_layers)]
        if self.dueling:
            self.value = (t[f"{self.head}.value.weight"].T.copy(), t[f"{self.head}.value.bias"])
            self.advantage = (t[f"{self.head}.advantage.weight"].T.copy(), t[f"{self.head}.advantage.bias"])
        else:
            self.out = (t[f"{self.head}.weight"].T.copy(), t[f"{self.head}.bias"])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, np.float32)
        h = x
        for w, b in self.layers:
            h = np.maximum(h @ w + b, 0.0)
        rows, heads, n = len(h), self.heads, self.n_actions
        if not self.dueling:
            q = (h @ self.out[0] + self.out[1]).reshape(rows, heads, n)
        else:
            adv = (h @ self.advantage[0] + self.advantage[1]).reshape(rows, heads, n)
            q = (h @ self.value[0] + self.value[1])[:, :, None] + adv - adv.mean(axis=2, keepdims=True)
        if heads == 1:
            return q[:, 0]
        return (q * x[:, -heads:, None]).sum(axis=1)  # laneshift.qnet.select_head: the one-hot's head


class _TorchNet:
    """The torch network (image observations), behind the same two methods as ``NumpyMLP``."""

    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, hidden: tuple[int, ...], dueling: bool,
                 threads: int, cnn: str = "nature"):
        import torch

        from laneshift.qnet import build_q_network

        torch.set_num_threads(threads)
        self.torch = torch
        self.net = build_q_network(obs_shape, n_actions, hidden, dueling, cnn).eval()

    def load(self, tensors: dict[str, np.ndarray]) -> None:
        from laneshift.qnet import load_into

        load_into(self.net, tensors)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        with self.torch.no_grad():
            return self.net(self.torch.as_tensor(obs)).numpy()


class QPolicy:
    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, hidden: tuple[int, ...], seed: int = 0,
                 dueling: bool = False, torch_threads: int = 1, cnn: str = "nature", heads: int = 1):
        if len(obs_shape) == 1:
            # One BLAS thread: OpenBLAS's thread pool made a 16-row forward pass 27x slower here
            # (3.9 ms vs 0.15 ms on 2 busy cores), and a worker has one core's share anyway.
            from threadpoolctl import threadpool_limits

            threadpool_limits(limits=torch_threads, user_api="blas")
            self.q = NumpyMLP(obs_shape[0], n_actions, tuple(hidden), dueling, heads)
        elif heads != 1:
            raise ValueError(f"heads: one Q head per road needs a vector observation (its one-hot), got {obs_shape}")
        else:
            self.q = _TorchNet(tuple(obs_shape), n_actions, tuple(hidden), dueling, torch_threads, cnn)
        self.n_actions = n_actions
        self.rng = np.random.default_rng(seed)
        self.version = -1
        self.phase = 0

    def load(self, weights: wire.Weights) -> None:
        self.load_tensors(weights.tensors)
        self.version, self.phase = weights.version, weights.phase

    def load_tensors(self, tensors: dict[str, np.ndarray]) -> None:
        """Weights by state-dict name (a checkpoint's tensors); ValueError for another network."""
        self.q.load(tensors)

    def greedy(self, obs: np.ndarray) -> np.ndarray:
        return self.q(obs).argmax(axis=1)

    def act(self, obs: np.ndarray, epsilon: float) -> np.ndarray:
        actions = self.greedy(obs)
        explore = self.rng.random(len(actions)) < epsilon
        actions[explore] = self.rng.integers(0, self.n_actions, size=int(explore.sum()))
        return actions
