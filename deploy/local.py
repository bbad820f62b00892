"""``laneshift train --local``: the whole system on this machine, in a private Ray cluster.

What it is: the local entry of the one launcher (``deploy.launch``); every component still runs
as its own Ray actor process, exactly as on a cluster.
Room: deploy, the wiring. May import: ``deploy.launch``.
"""

from __future__ import annotations

import sys
from typing import TextIO

from laneshift.config import RunConfig

from .launch import train


def train_local(cfg: RunConfig, out: TextIO = sys.stdout, *, resume: bool = False, overwrite: bool = False) -> int:
    return train(cfg, address=None, out=out, resume=resume, overwrite=overwrite)
