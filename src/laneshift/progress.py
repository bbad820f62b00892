"""Progress reporting for the long-running commands (eval, experiments, demos generate, benches).

Why this module exists: tqdm draws a bar with rate and ETA, which is right on a terminal, but
off a terminal (a CI log, ``ray job logs``, ``2> run.log``) its carriage-return redraws pile up as
one endless line, or as a line per redraw. So this one place decides: on a TTY a tqdm bar; off a
TTY the same numbers as a plain line at most every ``LANESHIFT_PROGRESS_S`` seconds (default 10).
Progress always goes to stderr, so JSON printed on stdout stays parseable. ``LANESHIFT_PROGRESS=0``
(or tqdm's own ``TQDM_DISABLE=1``) turns it off.

Room: the contract (shared by every process). May import: the standard library and tqdm only (the contract's modules and the CLI import this).

    with progress(total=episodes, desc="eval", unit="episode") as bar:
        for ep in range(episodes):
            ...
            bar.update()
"""

from __future__ import annotations

import os
import re
import sys
from typing import Any, Iterable, TextIO

from tqdm import tqdm

#: Seconds between two plain progress lines when stderr is not a terminal.
DEFAULT_INTERVAL_S = 10.0
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")
_PLAIN_FORMAT = "{desc}: {n_fmt}/{total_fmt} {unit} ({percentage:.0f} %) [{elapsed} elapsed, {remaining} left, {rate_fmt}]{postfix}"


class _Lines:
    """A file for tqdm off a terminal: each redraw becomes one whole line; cursor moves, clears
    and a repeat of the previous count and postfix (the closing redraw after the last update) are dropped."""

    def __init__(self, out: TextIO):
        self.out = out
        self.last = ""

    def write(self, text: str) -> None:
        for part in re.split(r"[\r\n]", _ANSI.sub("", str(text))):
            line = part.rstrip()
            # "desc: n/total unit (p %) [timings], postfix": a line is new when the count or the
            # postfix moved, not the timings alone.
            count = re.sub(r" \[[^\]]*\]", "", line)
            if line and count != self.last:
                self.out.write(line + "\n")
                self.last = count

    def flush(self) -> None:
        getattr(self.out, "flush", lambda: None)()


def _is_tty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _columns(stream: Any) -> int:
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, OSError, ValueError):
        return 0


def enabled() -> bool:
    return os.environ.get("LANESHIFT_PROGRESS", "1").strip().lower() not in ("0", "off", "false", "no")


def progress(iterable: Iterable | None = None, *, total: float | None = None, desc: str, unit: str = "it",
             leave: bool = True, disable: bool = False, file: TextIO | None = None, **kwargs: Any) -> tqdm:
    """A tqdm bar on stderr when it is a terminal, else plain periodic lines (see the module doc).

    Use it like tqdm: wrap an iterable, or ``with progress(total=n, desc=...) as bar: bar.update()``.
    ``disable=True`` gives a transparent no-op bar (so library code can always call ``update``).
    """
    out = file if file is not None else sys.stderr  # looked up now: tests and callers swap sys.stderr
    if disable or not enabled():
        return tqdm(iterable, total=total, disable=True)
    if _is_tty(out):
        # A pseudo-terminal may report a size of 0 x 0 (`script`, some containers): tqdm then draws nothing.
        width = {"dynamic_ncols": True} if _columns(out) > 0 else {"ncols": 100, "nrows": 50}
        return tqdm(iterable, total=total, desc=desc, unit=unit, leave=leave, file=out, **width, **kwargs)
    try:
        interval = float(os.environ.get("LANESHIFT_PROGRESS_S", DEFAULT_INTERVAL_S))
    except ValueError:
        interval = DEFAULT_INTERVAL_S
    if total is None and iterable is not None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    fmt = _PLAIN_FORMAT if total else "{desc}: {n_fmt} {unit} [{elapsed} elapsed, {rate_fmt}]{postfix}"
    # Off a terminal: nothing for a loop done within one interval (delay), then a line per interval,
    # and a last line when it ends (leave=True, also for inner loops: the log keeps the totals).
    return tqdm(iterable, total=total, desc=desc, unit=unit, leave=True, file=_Lines(out), mininterval=interval,
                maxinterval=max(interval, 10.0), delay=interval, ascii=True, ncols=200, bar_format=fmt, position=0,
                **kwargs)


def write(text: str, file: TextIO | None = None) -> None:
    """Print a line (to stdout by default), flushed, without breaking a bar that is being drawn."""
    out = file if file is not None else sys.stdout
    with tqdm.external_write_mode(file=out):
        out.write(text + "\n")
        getattr(out, "flush", lambda: None)()
