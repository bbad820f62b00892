"""Double DQN (van Hasselt et al. 2016), CleanRL style: the update reads top to bottom.

    >>> from laneshift.config import LearnerConfig
    >>> agent = DoubleDQN((4,), 2, LearnerConfig(hidden=(16,), batch_size=8))
    >>> import numpy as np
    >>> b = dict(obs=np.zeros((8, 4), np.float32), action=np.zeros(8, np.int64), reward=np.ones(8, np.float32),
    ...          next_obs=np.zeros((8, 4), np.float32), terminated=np.ones(8, np.uint8), steps=np.ones(8, np.uint8),
    ...          weight=np.ones(8, np.float32))
    >>> round(agent.update(b)["loss"], 3) > 0
    True
"""

from __future__ import annotations

import copy
from typing import Mapping

import numpy as np
import torch
import torch.nn.functional as F

from laneshift.config import LearnerConfig

from .networks import build_q_network


def resolve_device(name: str) -> torch.device:
    """``learner.device``: auto picks cuda when torch sees a GPU; cuda without one is refused."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("learner.device: cuda asked for, but torch sees no GPU on this node "
                         "(use learner.device=auto or cpu, or place the learner with deploy.learner_resources)")
    return torch.device(name)


class DoubleDQN:
    def __init__(self, obs_shape: tuple[int, ...], n_actions: int, cfg: LearnerConfig):
        torch.manual_seed(cfg.seed)
        self.cfg = cfg
        self.device = resolve_device(cfg.device)
        self.online = build_q_network(obs_shape, n_actions, cfg.hidden, cfg.dueling).to(self.device)
        self.target = copy.deepcopy(self.online).requires_grad_(False)
        self.updates = 0
        self.reset_optimizer()

    def reset_optimizer(self) -> None:
        """Fresh Adam and target = online: the start of a new training run (rehearsal phase 2)."""
        # Adam's coupled weight decay is plain L2 regularisation (MATLAB's L2RegularizationFactor).
        self.optimizer = torch.optim.Adam(self.online.parameters(), lr=self.cfg.lr, weight_decay=self.cfg.weight_decay)
        self.target.load_state_dict(self.online.state_dict())

    def state_dict(self) -> dict:
        """Everything a restarted learner needs to go on as if nothing happened (tensors only,
        so ``torch.load(weights_only=True)`` reads it back without unpickling code)."""
        return {"online": self.online.state_dict(), "target": self.target.state_dict(),
                "optimizer": self.optimizer.state_dict(), "updates": torch.tensor(self.updates)}

    def load_state_dict(self, state: dict) -> None:
        self.online.load_state_dict(state["online"])
        self.target.load_state_dict(state["target"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates = int(state["updates"])

    def update(self, batch: Mapping[str, np.ndarray]) -> dict[str, float]:
        dev = self.device
        obs = torch.as_tensor(batch["obs"], device=dev)
        action = torch.as_tensor(batch["action"], dtype=torch.int64, device=dev)
        reward = torch.as_tensor(batch["reward"], dtype=torch.float32, device=dev)
        next_obs = torch.as_tensor(batch["next_obs"], device=dev)
        not_done = 1.0 - torch.as_tensor(batch["terminated"], dtype=torch.float32, device=dev)
        # n-step items (laneshift.nstep) sum `steps` rewards: bootstrap with gamma ** steps. Required:
        # a silent default of 1 would bootstrap n-step returns with gamma and blow the values up.
        steps = torch.as_tensor(batch["steps"], dtype=torch.float32, device=dev)
        weight = torch.as_tensor(batch.get("weight", np.ones(len(reward), np.float32)), dtype=torch.float32,
                                 device=dev)

        # Q(s, a) of the actions taken.
        q_all = self.online(obs)
        q = q_all.gather(1, action[:, None]).squeeze(1)
        with torch.no_grad():
            # Double DQN: the online net picks the next action, the target net values it.
            chooser = self.online if self.cfg.double else self.target
            next_action = chooser(next_obs).argmax(dim=1, keepdim=True)
            next_q = self.target(next_obs).gather(1, next_action).squeeze(1)
            td_target = reward + torch.pow(self.cfg.gamma, steps) * not_done * next_q
        td_error = q - td_target
        loss = (weight * F.huber_loss(q, td_target, reduction="none", delta=self.cfg.huber_delta)).mean()
        margin_loss = bc_loss = torch.zeros((), device=dev)
        demo = torch.as_tensor(batch["is_demo"], dtype=torch.bool, device=dev) if "is_demo" in batch else None
        if demo is not None and demo.any():
            if self.cfg.margin_loss_weight > 0:
                # DQfD: on demo rows the demonstrator's action must beat every other by `margin`.
                qd = q_all[demo]
                penalty = torch.full_like(qd, self.cfg.margin)
                penalty.scatter_(1, action[demo][:, None], 0.0)
                margin_loss = ((qd + penalty).max(dim=1).values - q[demo]).mean()
                loss = loss + self.cfg.margin_loss_weight * margin_loss
            if self.cfg.bc_loss_weight > 0:
                # Supervised imitation: cross-entropy of softmax(Q(s, .)) against the demonstrator's
                # action on demo rows. Unlike the margin (a fixed 0.8 at Q-values near 100), it keeps
                # pushing until the demo action clearly leads, which is what makes the small action
                # gaps of 10 Hz control follow the demonstrator (docs/RESULTS.md).
                bc_loss = F.cross_entropy(q_all[demo], action[demo])
                loss = loss + self.cfg.bc_loss_weight * bc_loss

        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self.online.parameters(), self.cfg.grad_clip)
        self.optimizer.step()

        self.updates += 1
        if self.updates % self.cfg.target_update_period == 0:
            self.target.load_state_dict(self.online.state_dict())
        # Per-item |TD error|: the new priorities when the replay samples by priority.
        self.last_td_abs = td_error.detach().abs().cpu().numpy()
        return {"loss": float(loss.detach()), "q_mean": float(q.detach().mean()), "grad_norm": float(grad_norm),
                "td_abs": float(self.last_td_abs.mean()), "margin_loss": float(margin_loss.detach()),
                "bc_loss": float(bc_loss.detach())}

    @torch.no_grad()
    def greedy(self, obs: np.ndarray) -> np.ndarray:
        return self.online(torch.as_tensor(obs, device=self.device)).argmax(dim=1).cpu().numpy()
