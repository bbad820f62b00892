"""``laneshift train --cluster ADDRESS``: env workers as Ray actors on a running Ray cluster.

Run it on the cluster's head node (or any node the workers can reach). The zenoh router, replay
server and learner run as processes on this machine, exactly as in local mode; the Ray actors
are spread over the cluster and connect to the router at this machine's address. Every node
needs laneshift installed in the same environment (see ``deploy/ray-cluster.example.yaml``).

    laneshift train --cluster auto --workers 16 --scenario straight --mode rehearsal

The run summary's ``ray nodes`` line says which node ran each worker.
``tests/test_system_local.py::test_cluster_mode_spreads_workers_over_two_ray_nodes`` runs this
path against a two-node cluster (two raylets on one machine, ``ray.cluster_utils.Cluster``).
"""

from __future__ import annotations

import sys
from typing import TextIO

from laneshift.config import RunConfig

from .local import train_local


def head_address() -> str:
    """This node's address as Ray sees it (reachable by the other nodes)."""
    import ray.util

    return ray.util.get_node_ip_address()


def train_cluster(cfg: RunConfig, address: str, out: TextIO = sys.stdout, advertise_host: str | None = None) -> int:
    return train_local(cfg, out=out, ray_address=address, advertise_host=advertise_host or head_address())
