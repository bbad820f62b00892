"""``laneshift train --cluster ADDRESS``: the same launcher on a running Ray cluster.

What it is: how the address is chosen. ``auto`` (or ``RAY_ADDRESS``, which ``ray job submit``
sets) joins the cluster this node belongs to; ``HOST:PORT`` its GCS; ``ray://HOST:10001``
through Ray Client (``laneshift[cluster]``). Router, replay server, learner and env workers are
Ray actors placed by their ``deploy.*_resources``; the router listens on the address of the node
it landed on (``deploy.advertise_host`` to override) at ``deploy.router_port`` (7447 by default).
Room: deploy, the wiring. May import: ``deploy.launch``.

    laneshift train --cluster auto --workers 16 --scenario straight --mode rehearsal
"""

from __future__ import annotations

import os
import sys
from typing import TextIO

from laneshift.config import RunConfig

from .launch import train


def resolve_address(address: str) -> str:
    """``auto`` means RAY_ADDRESS when set (inside ``ray job submit``), else Ray's own lookup."""
    if address == "auto":
        return os.environ.get("RAY_ADDRESS") or "auto"
    return address


def train_cluster(cfg: RunConfig, address: str, out: TextIO = sys.stdout, *, resume: bool = False,
                  overwrite: bool = False) -> int:
    return train(cfg, address=resolve_address(address), out=out, resume=resume, overwrite=overwrite)
