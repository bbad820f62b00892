"""What the learner keeps on disk to go on after a restart, in ``<run dir>/checkpoints``:

- ``learner_state.pt``: the full training state (the agent with its optimizer, the weights
  version, the phase, the episode count, the run's env steps), written atomically;
- ``published_version``: the highest weights version ever broadcast and the update count it was
  published at, written before each broadcast, so that a restarted learner never reuses a
  version the env workers saw (they ignore versions they already passed);
- ``<name>.safetensors``: the policy network with its metadata (``latest``, ``final``,
  ``phase1``, ``u<updates>``), what ``laneshift eval`` and the studies read.

A write that fails (a full disk, a read-only run dir) is counted and said, never fatal: training
goes on and the next checkpoint retries.

Room: learner (component). May import: torch, the contract (``laneshift.qnet``, ``laneshift.checkpoints``);
never another component.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from laneshift.checkpoints import checkpoints_dir
from laneshift.qnet import save_checkpoint


class StateFiles:
    """The learner's files under ``<run dir>/checkpoints``; ``failures`` counts the writes that failed."""

    def __init__(self, run_dir: str | Path):
        self.dir = checkpoints_dir(run_dir)
        self.failures = 0

    @property
    def state_path(self) -> Path:
        return self.dir / "learner_state.pt"

    @property
    def version_path(self) -> Path:
        return self.dir / "published_version"

    # ------------------------------------------------------------------ the published version

    def read_published(self) -> tuple[int, int]:
        """(the highest weights version published, the update count it was published at); (-1, 0)
        if none was. A file of one number (written before the update count was kept) gives 0 updates."""
        try:
            fields = [int(x) for x in self.version_path.read_text().split()]
        except (OSError, ValueError):
            return -1, 0
        if not fields:
            return -1, 0
        return fields[0], fields[1] if len(fields) > 1 else 0

    def write_published(self, version: int, updates: int) -> None:
        """Before a broadcast of ``version``: a failed write is counted, and the broadcast goes on."""
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            tmp = self.version_path.with_suffix(".tmp")
            tmp.write_text(f"{version} {updates}")
            tmp.replace(self.version_path)
        except OSError as exc:
            self.failed("published version", exc)

    # ------------------------------------------------------------------ the full training state

    def load_state(self, device: torch.device | str) -> dict[str, Any] | None:
        """The last full training state, or None when none was saved."""
        if not self.state_path.exists():
            return None
        return torch.load(self.state_path, map_location=device, weights_only=True)

    def save_state(self, state: dict[str, Any]) -> bool:
        """Write the full training state atomically; False (counted) if the write failed."""
        tmp = self.state_path.with_suffix(".tmp")
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            torch.save(state, tmp)
            tmp.replace(self.state_path)  # the previous complete state stays valid until this rename
        except (OSError, RuntimeError) as exc:  # torch wraps ENOSPC in RuntimeError
            self.failed("learner state", exc)
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
            return False
        return True

    # ------------------------------------------------------------------ the policy checkpoints

    def save_policy(self, net: torch.nn.Module, name: str, meta: dict[str, Any]) -> Path | None:
        """``<name>.safetensors``: the policy network and ``meta``; None (counted) if the write failed."""
        try:
            return save_checkpoint(net, self.dir / f"{name}.safetensors", meta)
        except OSError as exc:  # a full disk or read-only run dir must not end training
            self.failed(f"{name} checkpoint", exc)
            return None

    def failed(self, what: str, exc: Exception) -> None:
        self.failures += 1
        print(f"learner: writing the {what} failed ({exc}); training goes on, retrying at the next checkpoint "
              f"({self.failures} failed so far)", flush=True)
