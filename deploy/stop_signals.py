"""``laneshift train``'s stop signals: SIGTERM and SIGINT set a flag the launcher polls, so a run
ends gracefully at any moment (final checkpoints, summary, nothing left running).

Room: deploy, the wiring. May import: the standard library.
"""

from __future__ import annotations

import signal
from typing import Any


class StopSignals:
    """SIGTERM and SIGINT set a flag the launcher polls, from before Ray starts to the end.

    Ray's driver installs its own SIGTERM handler (it aborts the process ~3 s later, cutting any
    cleanup short), so ``install()`` runs again once Ray is connected.
    """

    def __init__(self) -> None:
        self.received: int | None = None

    def install(self) -> "StopSignals":
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)
        return self

    def _on_signal(self, signum: int, _frame: Any) -> None:
        if self.received is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt  # a second Ctrl-C: stop waiting for the graceful end
        self.received = signum

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received else ""

    @staticmethod
    def restore() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL if sig == signal.SIGTERM else signal.default_int_handler)
