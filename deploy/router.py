"""The zenoh router every other laneshift process connects to as a client.

What it is: ``Router`` (a zenoh session in router mode on one endpoint), run by the Ray actor
``deploy.actors.RouterActor`` in a cluster run, inside the launcher's process in a local run
(``deploy.router_in``), and by ``laneshift router`` on its own.
Room: deploy, the wiring. May import: the contract (``laneshift.transport``) and zenoh; no component.

(On a cluster, ``zenohd`` works as well; this one needs nothing beyond the Python package.)
Clients reconnect by themselves when a router comes back on the same endpoint (measured: about
3 s after a restart, subscriptions and queryables redeclared), which is why a restarted router
must listen where the old one did.
"""

from __future__ import annotations

import signal
import threading

import zenoh

from laneshift.transport import DEFAULT_MAX_MESSAGE_BYTES, session_config, use_service_runtime


class Router:
    def __init__(self, listen: str, max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES):
        self.listen, self.max_message_bytes = listen, max_message_bytes
        self._session: zenoh.Session | None = None
        self.announce = True

    def start(self, announce: bool = True) -> "Router":
        """Listen; ``announce`` says so on stdout (not where the launcher hosts it: its console is the user's)."""
        use_service_runtime()
        self._session = zenoh.open(session_config(self.listen, "router", self.max_message_bytes))
        self.announce = announce
        if announce:
            print(f"router: listening on {self.listen}", flush=True)
        return self

    def close(self) -> None:
        if self._session is not None:
            self._session.close()
            self._session = None
            if self.announce:
                print("router: stopped", flush=True)


def run_router(listen: str) -> int:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    router = Router(listen).start()
    stop.wait()
    router.close()
    return 0
