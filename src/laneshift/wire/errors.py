"""The wire's one exception: a message that failed validation, with a stable reason label.

Its own module, the wire package's lowest: every codec raises it and the transport reports it, so it
imports nothing of the package.

Room: the contract (shared by every process). May import: the standard library only.
"""

from __future__ import annotations


class WireError(ValueError):
    """A message failed validation. ``reason`` is a short stable label for counters."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail
