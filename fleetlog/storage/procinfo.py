"""The process's CPU load and memory, as CMOOSApp puts them in an app's ``<APP>_STATUS``.

core-moos' ``ProcInfo`` reports ``cpuload`` (the process's user + system CPU time over wall
time, in percent), ``memory_kb`` (resident memory now) and ``memory_max_kb`` (peak resident
memory, ``ru_maxrss``), each printed with 4 significant digits. On Linux the resident memory
comes from ``/proc/self/statm``; elsewhere only the peak is known and stands for both.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Callable
from pathlib import Path

__all__ = ["ProcessMonitor"]

_STATM = Path("/proc/self/statm")


def _resident_kb() -> float | None:
    try:
        fields = _STATM.read_text(encoding="ascii").split()
        return int(fields[1]) * os.sysconf("SC_PAGE_SIZE") / 1024.0
    except (OSError, ValueError, IndexError):
        return None


class ProcessMonitor:
    """Measures CPU load between two readings, and memory now.

    Args:
        clock: a monotonic clock (seconds).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._last_cpu = self._cpu()
        self._last_time = clock()
        self._load = 0.0

    @staticmethod
    def _cpu() -> float:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return usage.ru_utime + usage.ru_stime

    def cpu_load(self) -> float:
        """Percent of one CPU used since the previous call (the last value if no time passed)."""
        now = self._clock()
        cpu = self._cpu()
        elapsed = now - self._last_time
        if elapsed > 0:
            self._load = 100.0 * (cpu - self._last_cpu) / elapsed
            self._last_cpu = cpu
            self._last_time = now
        return self._load

    def fields(self) -> str:
        """Return ``cpuload=…,memory_kb=…,memory_max_kb=…`` as CMOOSApp writes them."""
        peak_kb = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        now_kb = _resident_kb()
        if now_kb is None:
            now_kb = peak_kb
        return f"cpuload={self.cpu_load():.4g},memory_kb={now_kb:.4g},memory_max_kb={peak_kb:.4g}"
