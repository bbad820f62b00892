"""Where a run dir keeps its checkpoints, named once: the learner writes them (``learner/state.py``),
the launcher's summary, ``laneshift eval`` and the studies read them.

    >>> run_checkpoint("runs/demo").as_posix()
    'runs/demo/checkpoints/final.safetensors'
    >>> run_checkpoint("runs/demo", "u5000").name
    'u5000.safetensors'

Room: the contract (shared by every process). May import: the standard library only (no torch: the
launcher and the studies' command lines import it).
"""

from __future__ import annotations

from pathlib import Path


def checkpoints_dir(run_dir: str | Path) -> Path:
    """The run's checkpoint folder (networks, the learner's full state, the published version)."""
    return Path(run_dir) / "checkpoints"


def run_checkpoint(run_dir: str | Path, name: str = "final") -> Path:
    """A run's network by checkpoint name: ``final`` (the run's end), ``latest``, ``phase1``, ``u<updates>``."""
    return checkpoints_dir(run_dir) / f"{name}.safetensors"
