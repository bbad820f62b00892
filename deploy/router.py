"""``laneshift router``: a zenoh router every other laneshift process connects to as a client.

(On a cluster, ``zenohd`` works as well; this one needs nothing beyond the Python package.)
"""

from __future__ import annotations

import signal
import threading

import zenoh

from laneshift.transport import session_config, use_service_runtime


def run_router(listen: str) -> int:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    use_service_runtime()
    with zenoh.open(session_config(listen, "router")):
        print(f"router: listening on {listen}", flush=True)
        stop.wait()
    print("router: stopped", flush=True)
    return 0
