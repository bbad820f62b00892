"""Double DQN (van Hasselt et al. 2016), CleanRL style: the update reads top to bottom.

    >>> from laneshift.config import LearnerConfig
    >>> agent = DoubleDQN((4,), 2, LearnerConfig(hidden=(16,), batch_size=8))
    >>> import numpy as np
    >>> b = dict(obs=np.zeros((8, 4), np.float32), action=np.zeros(8, np.int64), reward=np.ones(8, np.float32),
    ...          next_obs=np.zeros((8, 4), np.float32), terminated=np.ones(8, np.uint8), steps=np.ones(8, np.uint8),
    ...          weight=np.ones(8, np.float32))
    >>> round(agent.update(b)["loss"], 3) > 0
    True

The update is written to cost what a bare torch loop costs (``laneshift bench learner``):

- the batch's arrays become tensors without copies (``torch.from_numpy``) where they already have
  the dtype the update needs, which is what the replay server sends (obs float32 / uint8, action
  int64, reward and weight float32); the two 1-byte columns ``steps`` and ``terminated`` become the
  bootstrap discount ``gamma ** steps * (1 - terminated)`` in one table lookup;
- nothing is read back per update: the metrics stay tensors (``UpdateMetrics``) and become Python
  floats only when somebody reads them (the learner loop: once per log interval), the per-row
  |TD error| likewise (``last_td_abs`` / ``last_td_abs_tensor``);
- the demo losses cost nothing unless they are switched on and the batch has demo rows;
- Adam is torch's fused implementation (``_ADAM_IMPL``, measured), built without importing
  ``torch._dynamo`` (``learner/optim.py``: 1.1 s of start-up and 73 MB), the gradient clipping the
  multi-tensor (``foreach``) one;
- the online network's pass over ``next_obs`` (Double DQN's chooser) is a separate no-grad pass on
  CPU and one pass over ``cat(obs, next_obs)`` on CUDA, see ``concat_online_pass``.

Room: learner (component). May import: the contract and laneshift.learner; never another component.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any, Iterator

import numpy as np
import torch
import torch.nn.functional as F

from laneshift.config import LearnerConfig

from laneshift.qnet import build_q_network

from torch.optim.swa_utils import get_ema_multi_avg_fn

from .augment import random_shift
from .optim import EagerAdam

#: The metrics every update returns, in this order.
METRIC_NAMES = ("loss", "q_mean", "grad_norm", "td_abs", "margin_loss", "bc_loss")

# Adam's implementation, chosen by measurement. torch's CPU default is the per-parameter for-loop;
# "foreach" (multi-tensor kernels) and "fused" (one kernel over all parameters, on CPU since torch
# 2.4) do the same arithmetic in fewer dispatches. Measured on the 2-core AMD EPYC dev machine,
# 1 torch thread, alternating rounds, updates per CPU-second relative to the bare loop with
# torch's default Adam (`laneshift bench learner`'s bare torch): MLP b256 (89 k parameters)
# fused 1.11 / 1.03, foreach 0.98 / 1.01, for-loop 0.98 / 1.00 (two separate sessions); Nature CNN b32
# (2.7 M parameters) fused 1.22, foreach 1.16, for-loop 1.05. Fused is the fastest on CPU, most
# of all for the large CNN, and it is torch's fast path on CUDA too; elsewhere foreach. To measure:
# `laneshift bench learner --cases mlp-b256,cnn-b32 --rounds 3 --seconds 2`.
_ADAM_IMPL = "fused"


class _UpdateRecord:
    """What one update leaves behind for later reads: detached Q(s, a) and TD targets, and the
    per-row |TD error| computed from them when first asked for (priorities, metrics)."""

    __slots__ = ("q", "td_target", "_td_abs")

    def __init__(self, q: torch.Tensor, td_target: torch.Tensor):
        self.q, self.td_target, self._td_abs = q, td_target, None

    def td_abs(self) -> torch.Tensor:
        if self._td_abs is None:
            self._td_abs = (self.q - self.td_target).abs_()
        return self._td_abs


class UpdateMetrics(Mapping):
    """One update's metrics (``METRIC_NAMES``) as a read-only mapping of Python floats.

    The values stay tensors (no reductions, no read-back) until any of them is read; then all are
    computed and converted at once (one ``.tolist()``: one device sync on CUDA). The learner loop
    reads the last update's metrics once per log interval, so the other updates cost nothing here.
    """

    __slots__ = ("_parts", "_floats")

    def __init__(self, loss: torch.Tensor, grad_norm: torch.Tensor, margin_loss: torch.Tensor,
                 bc_loss: torch.Tensor, record: _UpdateRecord):
        self._parts: tuple | None = (loss, grad_norm, margin_loss, bc_loss, record)
        self._floats: dict[str, float] | None = None

    def tensor(self) -> torch.Tensor:
        """The values as one tensor in ``METRIC_NAMES`` order (on the learner's device, no read-back)."""
        if self._parts is None:
            return torch.tensor([self._floats[k] for k in METRIC_NAMES])  # type: ignore[index]
        loss, grad_norm, margin_loss, bc_loss, record = self._parts
        with torch.no_grad():
            return torch.stack([loss, record.q.mean(), grad_norm.to(loss.dtype), record.td_abs().mean(),
                                margin_loss, bc_loss])

    def _read(self) -> dict[str, float]:
        if self._floats is None:
            self._floats = dict(zip(METRIC_NAMES, self.tensor().tolist()))
            self._parts = None
        return self._floats

    def __getitem__(self, key: str) -> float:
        return self._read()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(METRIC_NAMES)

    def __len__(self) -> int:
        return len(METRIC_NAMES)

    def __repr__(self) -> str:
        return f"UpdateMetrics({self._read()!r})"


def resolve_device(name: str) -> torch.device:
    """``learner.device``: auto picks cuda when torch sees a GPU; cuda without one is refused."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("learner.device: cuda asked for, but torch sees no GPU on this node "
                         "(use learner.device=auto or cpu, or place the learner with deploy.learner_resources)")
    return torch.device(name)


def _tensor(arr: Any, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``arr`` as a tensor of ``dtype`` on ``device``; a writable numpy array of that dtype is shared
    (``torch.from_numpy``, no copy) and then moved in one copy to a non-CPU device."""
    if isinstance(arr, np.ndarray) and arr.flags.writeable and arr.dtype == _NP_DTYPES.get(dtype):
        t = torch.from_numpy(arr)
        return t if device.type == "cpu" else t.to(device, non_blocking=True)
    return torch.as_tensor(np.asarray(arr), dtype=dtype, device=device)


_NP_DTYPES = {torch.float32: np.dtype(np.float32), torch.int64: np.dtype(np.int64), torch.uint8: np.dtype(np.uint8),
              torch.bool: np.dtype(np.bool_)}


class DoubleDQN:
    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, cfg: LearnerConfig):
        torch.manual_seed(cfg.seed)
        self.cfg = cfg
        self.device = resolve_device(cfg.device)
        self.online = build_q_network(obs_shape, n_actions, cfg.hidden, cfg.dueling, cfg.network_cnn,
                                      cfg.cnn_precision, cfg.heads, cfg.mlp_precision).to(self.device)
        self.target = copy.deepcopy(self.online).requires_grad_(False)
        self._params = list(self.online.parameters())
        # Weight averaging (learner.ema_decay): an exponential moving average of the online weights,
        # the network the run hands out (``policy_net``). torch's own EMA arithmetic
        # (swa_utils.get_ema_multi_avg_fn: one foreach lerp) on fixed parameter lists; not
        # swa_utils.AveragedModel itself, whose update_parameters reads a counter tensor back on
        # every call (a device sync per update on CUDA) and regroups the tensors each time.
        self.averaged: torch.nn.Module | None = None
        if cfg.ema_decay > 0:
            self.averaged = copy.deepcopy(self.online).requires_grad_(False)
            self._averaged_params = list(self.averaged.parameters())
            self._ema = get_ema_multi_avg_fn(cfg.ema_decay)
        # The networks hold no BatchNorm, dropout or other batch- or mode-dependent layer (only
        # Linear, Conv2d, ReLU, Flatten, the dueling head's per-row mean), so a row's Q-values do not
        # depend on the other rows of the pass: one pass over cat(obs, next_obs) equals two passes.
        row_independent = all(
            isinstance(m, (torch.nn.Linear, torch.nn.Conv2d, torch.nn.ReLU, torch.nn.Flatten, torch.nn.Sequential))
            or type(m).__name__ in ("MLPQNetwork", "NatureCNN", "DuelingHead") for m in self.online.modules())
        # Double DQN's chooser Q_online(s', .): one online pass over cat(obs, next_obs), or a second
        # no-grad pass over next_obs. On CPU the second pass is the faster (measured, MLP batch 256,
        # 1 thread, three alternating sessions, updates per CPU-second relative to the bare loop:
        # one concatenated pass 0.83 / 0.92 / 0.94, two passes 1.04 / 1.11 / 1.03): the
        # update is bound by its matmuls, and in one pass next_obs joins the autograd graph, so
        # every backward matmul runs over twice the rows (half of them zero gradients), plus the
        # cat's copy. On CUDA the update is bound by kernel launches, which one pass saves (about
        # 6 of the online forward's); that choice is not measured yet (no GPU in the runs of
        # `laneshift bench learner`, which measures the update against a bare torch loop).
        # Both give the same target (tests/test_dqn_reference.py checks both).
        self.concat_online_pass = self.device.type == "cuda" and cfg.double and row_independent
        # The bootstrap discount per (steps, terminated) pair, gamma ** steps * (1 - terminated),
        # computed as the update used to (torch.pow in float32), looked up per row in numpy: one
        # operation instead of two dtype conversions, a pow and a product per update.
        k = torch.arange(256, dtype=torch.float32)
        powers, zeros = torch.pow(cfg.gamma, k), torch.zeros(256)
        self._discount_table = torch.stack([powers, zeros], dim=1).numpy()  # [steps, terminated != 0]
        # learner.terminal_value bootstrapped after a terminal step, by the same lookup: gamma ** steps
        # * terminal_value where the row ended its episode, 0 where it did not.
        self._terminal_table = torch.stack([zeros, powers * cfg.terminal_value], dim=1).numpy()
        # learner.augment=shift (DrQ): its own generator, so the shifts repeat for a seed whatever
        # else draws from torch's global one.
        self._augment_gen: torch.Generator | None = None
        if cfg.augment == "shift" and len(obs_shape) == 3:
            self._augment_gen = torch.Generator().manual_seed(cfg.seed + 1)
        self.updates = 0
        # The factor on both imitation losses (learner.imitation_final's schedule, set by the loop).
        self.imitation_scale = 1.0
        # Whether an update trains the TD loss (the loop turns it off for phase 1 with
        # learner.phase1_td=false: the imitation losses alone).
        self.td_loss = True
        # Whether learner.frozen_layers are frozen (learner.frozen_steps' schedule, set by the loop).
        self.frozen = False
        # Frozen all-but-output with the target's trunk equal to the online one's: one trunk pass
        # over next_obs serves both Double DQN's chooser and the target (``update``'s first branch).
        self.shared_trunk = False
        self._last: _UpdateRecord | None = None
        self.reset_optimizer()

    def reset_optimizer(self) -> None:
        """Fresh Adam and target = online (and the average restarted there): the start of a new
        training run (rehearsal phase 2)."""
        # Adam's coupled weight decay is plain L2 regularisation (MATLAB's L2RegularizationFactor).
        self.optimizer = EagerAdam(self._params, lr=self.cfg.lr, weight_decay=self.cfg.weight_decay,
                                   **self._adam_impl())
        self.target.load_state_dict(self.online.state_dict())
        if self.averaged is not None:
            self.averaged.load_state_dict(self.online.state_dict())
        self._check_shared_trunk()

    @property
    def policy_net(self) -> torch.nn.Module:
        """The network the run hands out (published weights, checkpoints, greedy evaluation): the
        weight average with ``learner.ema_decay``, else the online network."""
        return self.averaged if self.averaged is not None else self.online

    @property
    def lr(self) -> float:
        return float(self.optimizer.param_groups[0]["lr"])

    def set_lr(self, lr: float) -> None:
        """The step size from now on (``learner.lr_final``'s schedule)."""
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    def state_dict(self) -> dict:
        """Everything a restarted learner needs to go on as if nothing happened (tensors only,
        so ``torch.load(weights_only=True)`` reads it back without unpickling code)."""
        state = {"online": self.online.state_dict(), "target": self.target.state_dict(),
                 "optimizer": self.optimizer.state_dict(), "updates": torch.tensor(self.updates)}
        if self.averaged is not None:
            state["averaged"] = self.averaged.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        self.online.load_state_dict(state["online"])
        self.target.load_state_dict(state["target"])
        if self.averaged is not None:  # a state saved without averaging restarts the average at online
            self.averaged.load_state_dict(state.get("averaged", state["online"]))
        self._check_shared_trunk()
        self.optimizer.load_state_dict(state["optimizer"])
        # A saved param group carries its own foreach/fused flags (a state written before Adam's
        # implementation was chosen here has the for-loop's None): the implementation is this
        # code's choice, not the checkpoint's.
        for group in self.optimizer.param_groups:
            group.update(self._adam_impl())
        self.updates = int(state["updates"])

    def _adam_impl(self) -> dict[str, bool | None]:
        if _ADAM_IMPL == "fused" and _fused_ok(self.device):
            return {"fused": True, "foreach": None}
        return {"fused": None, "foreach": _ADAM_IMPL == "foreach"}

    def set_frozen(self, frozen: bool) -> None:
        """Freeze or thaw the online frame network's ``learner.frozen_layers`` (``learner.frozen_steps``):
        frozen, they get no gradient, so backward stops at the layers after them, Adam and the weight
        decay skip them (their gradients are None) and the gradient norm is the rest's."""
        net = self.online
        if not hasattr(net, "features"):
            raise ValueError("learner.frozen_steps: the network has no frame layers to freeze (a vector MLP)")
        if frozen == self.frozen:
            return
        if self.cfg.frozen_layers == "convolutions":
            net.features.requires_grad_(not frozen)
        else:  # all-but-output: everything, then the output layer (the dueling head's or the plain one) back on
            net.requires_grad_(not frozen)
            net.head[-1].requires_grad_(True)
        self.frozen = frozen
        self._check_shared_trunk()

    def _check_shared_trunk(self) -> None:
        """Set ``shared_trunk``: frozen all-but-output (the online trunk no longer changes) under
        Double DQN, and the target's trunk the same weights (it is from the first target sync on)."""
        online, target = self.online, self.target
        self.shared_trunk = bool(
            self.frozen and self.cfg.frozen_layers == "all-but-output" and self.cfg.double
            and hasattr(online, "trunk")
            and all(torch.equal(a, b) for a, b in zip(online.head[:-1].parameters(), target.head[:-1].parameters()))
            and all(torch.equal(a, b) for a, b in zip(online.features.parameters(), target.features.parameters())))

    @property
    def last_td_abs_tensor(self) -> torch.Tensor | None:
        """Per-row |TD error| of the last update (float32, on the learner's device), computed when
        first asked for: the new priorities for a prioritized replay."""
        return None if self._last is None else self._last.td_abs()

    @property
    def last_td_abs(self) -> np.ndarray | None:
        """``last_td_abs_tensor`` as a numpy array."""
        t = self.last_td_abs_tensor
        return None if t is None else t.cpu().numpy()

    def _discount(self, steps: Any, terminated: Any) -> torch.Tensor:
        # n-step items (laneshift.nstep) sum `steps` rewards: bootstrap with gamma ** steps. Required:
        # a silent default of 1 would bootstrap n-step returns with gamma and blow the values up.
        steps, terminated = np.asarray(steps), np.asarray(terminated)
        if steps.dtype == np.uint8 and terminated.dtype.kind in "biu":
            disc = self._discount_table[steps, (terminated != 0).view(np.uint8)]
            return _tensor(disc, torch.float32, self.device)
        dev = self.device
        not_done = 1.0 - torch.as_tensor(terminated, dtype=torch.float32, device=dev)
        return torch.pow(self.cfg.gamma, torch.as_tensor(steps, dtype=torch.float32, device=dev)) * not_done

    def _terminal_value(self, steps: Any, terminated: Any) -> torch.Tensor:
        """``learner.terminal_value`` discounted to each row that ended its episode (a crash, leaving
        the road), 0 elsewhere: one lookup in ``_terminal_table``, as ``_discount`` does."""
        done = (np.asarray(terminated) != 0).view(np.uint8)
        rows = self._terminal_table[np.asarray(steps).astype(np.intp, copy=False), done]
        return _tensor(rows, torch.float32, self.device)

    def update(self, batch: Mapping[str, np.ndarray]) -> UpdateMetrics:
        if not self.td_loss:
            return self._imitation_update(batch)
        if "next_obs" not in batch:
            raise ValueError("DoubleDQN.update: the TD loss needs next_obs, and this batch was sampled without "
                             "(wire.SampleRequest(next_obs=False) is for updates of the imitation losses alone)")
        cfg, dev = self.cfg, self.device
        obs = _tensor(batch["obs"], _obs_dtype(batch["obs"]), dev)
        next_obs = _tensor(batch["next_obs"], _obs_dtype(batch["next_obs"]), dev)
        action = _tensor(batch["action"], torch.int64, dev)
        reward = _tensor(batch["reward"], torch.float32, dev)
        discount = self._discount(batch["steps"], batch["terminated"])
        weight = batch.get("weight")
        rows = reward.shape[0]
        if self._augment_gen is not None:
            # DrQ: the online pass and the target see independently shifted frames.
            obs = random_shift(obs, cfg.augment_pad, self._augment_gen)
            next_obs = random_shift(next_obs, cfg.augment_pad, self._augment_gen)

        # Q(s, .) with grad; Double DQN's chooser Q_online(s', .) without.
        q_next_target = None
        if self.shared_trunk:
            # Frozen all-but-output: the trunk (convolutions and hidden layer) without grad over obs
            # and next_obs in one pass, and next_obs' features feed the online and the target output
            # layers alike (the two trunks are equal): 2 trunk passes of the batch where the general
            # path makes 3, the same Q-values to float rounding.
            with torch.no_grad():
                h = self.online.trunk(torch.cat([obs, next_obs]))
            q_all = self.online.output(h[:rows])
            with torch.no_grad():
                q_next_online, q_next_target = self.online.output(h[rows:]), self.target.output(h[rows:])
        elif self.concat_online_pass:
            q_both = self.online(torch.cat([obs, next_obs]))
            q_all, q_next_online = q_both[:rows], q_both[rows:].detach()
        else:
            q_all = self.online(obs)
            q_next_online = None
        q = q_all.gather(1, action[:, None]).squeeze(1)
        with torch.no_grad():
            if q_next_target is None:
                q_next_target = self.target(next_obs)
            if cfg.double:
                # Double DQN: the online net picks the next action, the target net values it.
                if q_next_online is None:
                    q_next_online = self.online(next_obs)
                next_q = q_next_target.gather(1, q_next_online.argmax(dim=1, keepdim=True)).squeeze(1)
            else:  # vanilla DQN: the target net picks and values (its value at its own argmax)
                next_q = q_next_target.max(dim=1).values
            td_target = reward + discount * next_q
            if cfg.terminal_value:
                # After a crash the target bootstraps learner.terminal_value instead of nothing.
                td_target = td_target + self._terminal_value(batch["steps"], batch["terminated"])
        huber = F.huber_loss(q, td_target, reduction="none", delta=cfg.huber_delta)
        loss = (huber * _tensor(weight, torch.float32, dev)).mean() if weight is not None else huber.mean()
        loss, margin_loss, bc_loss = self._add_imitation(loss, q_all, action, batch.get("is_demo"))
        return self._step(loss, q, td_target, margin_loss, bc_loss)

    def _add_imitation(self, loss: torch.Tensor, q_all: torch.Tensor, action: torch.Tensor,
                       demo_np: np.ndarray | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``loss`` plus the weighted imitation losses on the batch's demo rows, and the two losses
        (margin, cross-entropy) unweighted: 0 for one whose weight is 0, or when no row is a demo row."""
        cfg, dev = self.cfg, self.device
        margin_loss = bc_loss = q_all.new_zeros(())
        margin_weight = cfg.margin_loss_weight * self.imitation_scale
        bc_weight = cfg.bc_loss_weight * self.imitation_scale
        if demo_np is not None and (margin_weight > 0 or bc_weight > 0) and np.any(demo_np):
            demo = _tensor(np.asarray(demo_np) != 0, torch.bool, dev)
            qd, ad = q_all[demo], action[demo]
            if margin_weight > 0:
                # DQfD: on demo rows the demonstrator's action must beat every other by `margin`.
                penalty = torch.full_like(qd, cfg.margin)
                penalty.scatter_(1, ad[:, None], 0.0)
                margin_loss = ((qd + penalty).max(dim=1).values - qd.gather(1, ad[:, None]).squeeze(1)).mean()
                loss = loss + margin_weight * margin_loss
            if bc_weight > 0:
                # Supervised imitation: cross-entropy of softmax(Q(s, .)) against the demonstrator's
                # action on demo rows. Unlike the margin (a fixed 0.8 at Q-values near 100), it keeps
                # pushing until the demo action clearly leads, which is what makes the small action
                # gaps of 10 Hz control follow the demonstrator (docs/results-history.md, round 2).
                bc_loss = F.cross_entropy(qd, ad)
                loss = loss + bc_weight * bc_loss
        return loss, margin_loss, bc_loss

    def _imitation_update(self, batch: Mapping[str, np.ndarray]) -> UpdateMetrics:
        """One update of the imitation losses alone (phase 1 with learner.phase1_td=false): one
        pass over the observations, none over the next ones or the target network. Its record's TD
        target is Q(s, a) itself, so its |TD error| reads 0 (no priorities: the config refuses the
        prioritized sampler with it)."""
        cfg, dev = self.cfg, self.device
        obs = _tensor(batch["obs"], _obs_dtype(batch["obs"]), dev)
        action = _tensor(batch["action"], torch.int64, dev)
        if self._augment_gen is not None:
            obs = random_shift(obs, cfg.augment_pad, self._augment_gen)
        q_all = self.online(obs)
        q = q_all.gather(1, action[:, None]).squeeze(1)
        loss, margin_loss, bc_loss = self._add_imitation(q_all.new_zeros(()), q_all, action, batch.get("is_demo"))
        return self._step(loss, q, q.detach(), margin_loss, bc_loss)

    def _step(self, loss: torch.Tensor, q: torch.Tensor, td_target: torch.Tensor, margin_loss: torch.Tensor,
              bc_loss: torch.Tensor) -> UpdateMetrics:
        """The optimizer step on ``loss``, the weight average, the target's refresh, the record."""
        cfg = self.cfg
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self._params, cfg.grad_clip, foreach=True)
        self.optimizer.step()
        if self.averaged is not None:
            self._ema(self._averaged_params, self._params, self.updates)

        self.updates += 1
        if self.updates % cfg.target_update_period == 0:
            self.target.load_state_dict(self.online.state_dict())
            if self.frozen and not self.shared_trunk:
                self._check_shared_trunk()
        # Per-item |TD error| (the new priorities when the replay samples by priority) and the
        # metrics are computed from these only when read.
        self._last = _UpdateRecord(q.detach(), td_target)
        return UpdateMetrics(loss.detach(), grad_norm, margin_loss.detach(), bc_loss.detach(), self._last)

    @torch.no_grad()
    def greedy(self, obs: np.ndarray) -> np.ndarray:
        return self.policy_net(torch.as_tensor(obs, device=self.device)).argmax(dim=1).cpu().numpy()


def _obs_dtype(arr: Any) -> torch.dtype:
    """Observations keep their dtype (float32 vectors, uint8 frames; the networks convert)."""
    dtype = getattr(arr, "dtype", None)
    return torch.uint8 if dtype == np.uint8 else torch.float32


def _fused_ok(device: torch.device) -> bool:
    """Fused Adam exists for CPU and CUDA float tensors in this torch (2.4+)."""
    return device.type in ("cpu", "cuda")
