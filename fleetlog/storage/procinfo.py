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
import weakref
from collections.abc import Callable

__all__ = ["ProcessMonitor", "Statm"]

_STATM = "/proc/self/statm"
_PAGE_KB = os.sysconf("SC_PAGE_SIZE") / 1024.0


class Statm:
    """``/proc/self/statm``, kept open and read again from its start (``pread``).

    Opening it through ``pathlib`` each time cost an idle recorder about 0.25 ms of CPU per
    status post (an open file object, two ``fstat``s, a text decoder; all cold after a 2 s
    sleep): a third of what its PLOGGER_STATUS cost. The kernel builds the text anew at
    every read from offset 0. (A forked child opens its own: the descriptor names the
    process that opened it.)
    """

    def __init__(self) -> None:
        self._fd: int | None = None
        self._pid = 0
        #: closes the descriptor once, by :meth:`close` or when this object is collected
        self._closer: weakref.finalize[[int], Statm] | None = None

    def pages(self) -> int | None:
        """Return the resident size in pages (None where ``/proc`` does not say)."""
        try:
            fd = self._fd
            if fd is None or self._pid != os.getpid():
                self.close()
                fd = self._fd = os.open(_STATM, os.O_RDONLY | os.O_CLOEXEC)
                self._pid = os.getpid()
                self._closer = weakref.finalize(self, os.close, fd)
            return int(os.pread(fd, 256, 0).split()[1])
        except (OSError, ValueError, IndexError):
            return None

    def resident_kb(self) -> float | None:
        """Return the resident size in kB (None where ``/proc`` does not say)."""
        pages = self.pages()
        return None if pages is None else pages * _PAGE_KB

    def close(self) -> None:
        """Close the descriptor (opened again at the next read)."""
        closer, self._closer, self._fd = self._closer, None, None
        if closer is not None:
            closer()


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
        self._statm = Statm()

    @staticmethod
    def _cpu(usage: resource.struct_rusage | None = None) -> float:
        if usage is None:
            usage = resource.getrusage(resource.RUSAGE_SELF)
        return usage.ru_utime + usage.ru_stime

    def cpu_load(self, usage: resource.struct_rusage | None = None) -> float:
        """Percent of one CPU used since the previous call (the last value if no time passed).

        ``usage``: the process's ``getrusage`` just taken (read here otherwise).
        """
        now = self._clock()
        cpu = self._cpu(usage)
        elapsed = now - self._last_time
        if elapsed > 0:
            self._load = 100.0 * (cpu - self._last_cpu) / elapsed
            self._last_cpu = cpu
            self._last_time = now
        return self._load

    def fields(self) -> str:
        """Return ``cpuload=…,memory_kb=…,memory_max_kb=…`` as CMOOSApp writes them."""
        usage = resource.getrusage(resource.RUSAGE_SELF)
        peak_kb = float(usage.ru_maxrss)
        now_kb = self._statm.resident_kb()
        if now_kb is None:
            now_kb = peak_kb
        load = self.cpu_load(usage)
        return f"cpuload={load:.4g},memory_kb={now_kb:.4g},memory_max_kb={peak_kb:.4g}"
