"""CPU used by processes over a window, from /proc: cores per role (each a list of pids), this
process (``bench``), the whole machine and everything else on it (``other``), so that a slow
benchmark figure can be attributed. Linux only; a figure that cannot be read is None.

    >>> meter = CpuMeter({"server": [server_pid]})  # doctest: +SKIP
    >>> ...  # the window
    >>> meter.cores()  # doctest: +SKIP
    {'server': 0.97, 'bench': 0.05, 'machine': 1.4, 'other': 0.38}

Room: the tools (benchmarks). May import: the standard library only.
"""

from __future__ import annotations

import os
import time

_CLK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def proc_cpu_s(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / _CLK  # utime + stime
    except (OSError, IndexError, ValueError):
        return None


def machine_busy_s() -> float | None:
    try:
        with open("/proc/stat") as f:
            vals = [int(v) for v in f.readline().split()[1:]]
        return (sum(vals[:8]) - vals[3] - vals[4]) / _CLK  # everything but idle and iowait
    except (OSError, IndexError, ValueError):
        return None


class CpuMeter:
    """Cores used per role over the window since it was made (``cores``), by this process (role
    ``bench``) and by the whole machine."""

    def __init__(self, roles: dict[str, list[int]]):
        self.roles = {**roles, "bench": [os.getpid()]}
        self.t0 = time.monotonic()
        self.start = self._snap()

    def _snap(self) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for role, pids in self.roles.items():
            vals = [proc_cpu_s(pid) for pid in pids]
            out[role] = None if any(v is None for v in vals) else sum(vals)  # type: ignore[arg-type]
        out["machine"] = machine_busy_s()
        return out

    def cores(self) -> dict[str, float | None]:
        end, wall = self._snap(), time.monotonic() - self.t0
        res = {k: (None if end[k] is None or self.start[k] is None else round((end[k] - self.start[k]) / wall, 2))
               for k in end}
        ours = [res[k] for k in self.roles]
        if res["machine"] is not None and all(v is not None for v in ours):
            res["other"] = round(max(0.0, res["machine"] - sum(ours)), 2)  # type: ignore[operator]
        return res
