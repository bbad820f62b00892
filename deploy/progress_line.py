"""``laneshift train``'s live status line, from the learner's status: env steps against the
budget, episodes, updates, loss, replay size, weights version and each worker's lag (one line
redrawn on a terminal, a line each time otherwise), and the launcher's messages on lines of their own.

Room: deploy, the wiring. May import: the standard library.
"""

from __future__ import annotations

import time
from typing import TextIO


class Progress:
    """One live status line from the learner's status."""

    def __init__(self, out: TextIO, budget: int):
        self.out, self.budget = out, budget
        self.tty = hasattr(out, "isatty") and out.isatty()
        self.last: dict = {}
        self.started = time.monotonic()

    def line(self) -> str:
        s = self.last
        if not s:
            return f"[{time.monotonic() - self.started:6.1f}s] starting ..."
        elapsed = time.monotonic() - self.started
        fmt = lambda v, f: format(v, f) if isinstance(v, (int, float)) else "-"  # noqa: E731
        lag = s.get("version_lag") or {}
        # The learner's own rate over its last status interval, as for updates: env_steps / elapsed
        # would count the steps a resumed run had made before this launch as made now.
        return (f"[{elapsed:6.1f}s] steps {s.get('env_steps', 0):>7,}/{self.budget:,}"
                f" ({fmt(s.get('env_steps_per_s'), '5.0f')}/s)"
                f" | ep {s.get('episodes', 0):>5} return {fmt(s.get('return_mean'), '7.2f')}"
                f" crash {fmt(s.get('crash_rate'), '.2f')}"
                f" | upd {s.get('updates', 0):>6,} ({fmt(s.get('updates_per_s'), '.0f')}/s)"
                f" loss {fmt(s.get('loss'), '.4f')} q {fmt(s.get('q_mean'), '.2f')}"
                f" | replay {fmt(s.get('replay_size'), ',')} | v{s.get('version', 0)} phase {s.get('phase', 0)}"
                f" lag {'/'.join(str(lag[k]) for k in sorted(lag)[:8]) or '-'}")

    def show(self) -> None:
        self.out.write(("\r\033[K" if self.tty else "") + self.line() + ("" if self.tty else "\n"))
        self.out.flush()

    def say(self, text: str) -> None:
        """A message on its own line (not overwritten by the next progress line)."""
        self.out.write(("\n" if self.tty else "") + text + "\n")
        self.out.flush()
