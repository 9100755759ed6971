"""Giving the C heap's freed pages back to the system, so resident memory follows use.

A recorder at 20,000 samples a second holds, for moments, 50-150 MiB more of C heap than it
otherwise uses: Zenoh's receive buffers while samples wait in the subscriber's FIFO, file
ranges on their way out (bytes, then Zenoh's copy), each in the arena of the thread that
allocated it. glibc keeps what is freed inside its arenas and returns only an arena's top
to the system, so each such moment left the resident size at a new high that never came
down (``bench/soak.py``: 160 → 330 MiB in five minutes while the C heap in use stayed at
16 MiB and the Python heap at 34 MiB). ``malloc_trim(0)`` gives every whole free page of
every arena back (``madvise(MADV_DONTNEED)``).

:class:`HeapKeeper` does so from a thread of its own when the resident size has grown by
``grow`` since the last trim, and at most once a ``settle`` period while it stays ``grow``
above the lowest it was seen at (a trim in the middle of a burst gives little back; what the
burst frees afterwards is given back then). A trim locks one arena at a time for
milliseconds, never the GIL (``ctypes`` releases it).
Where the C library has no ``malloc_trim`` (musl, macOS) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading
import time
from collections.abc import Callable

from fleetlog.storage.procinfo import Statm

__all__ = ["HeapKeeper", "resident_bytes", "trim_heap"]

#: resident growth (bytes) since the lowest seen that makes the keeper trim
GROW = 32 << 20
#: seconds between two looks at the resident size
EVERY = 5.0
#: seconds after a trim before the resident size above its lowest makes the keeper trim again
SETTLE = 20.0


def _load_trim() -> Callable[[int], int] | None:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        trim = libc.malloc_trim
    except (OSError, AttributeError, TypeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


_TRIM = _load_trim()


def trim_heap() -> bool:
    """Give the C heap's free pages back to the system; False if this C library cannot."""
    if _TRIM is None:
        return False
    _TRIM(0)
    return True


#: kept open: a keeper looks every few seconds, each time with cold caches
_STATM = Statm()
_PAGE = os.sysconf("SC_PAGE_SIZE")


def resident_bytes() -> int | None:
    """Return this process's resident size in bytes (None where ``/proc`` does not say)."""
    pages = _STATM.pages()
    return None if pages is None else pages * _PAGE


class HeapKeeper:
    """Trims the C heap when the resident size grew by ``grow`` bytes (see the module doc).

    Use it as a context manager (a daemon thread looks every ``every`` seconds), or call
    :meth:`check` yourself. ``stats`` counts ``trims`` and ``released`` (resident bytes
    that each trim gave back, summed).

    Args:
        grow: resident growth, in bytes, that makes it trim.
        every: seconds between two looks.
        settle: seconds after a trim before staying ``grow`` above the lowest trims again.
        resident: reads the resident size (tests pass their own).
        trim: trims the heap; returns False if it cannot (tests pass their own).
    """

    def __init__(
        self,
        *,
        grow: int = GROW,
        every: float = EVERY,
        settle: float = SETTLE,
        resident: Callable[[], int | None] = resident_bytes,
        trim: Callable[[], bool] = trim_heap,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._grow = grow
        self._every = every
        self._settle = settle
        self._resident = resident
        self._trim = trim
        self._clock = clock
        self._lowest: int | None = None
        self._after: int | None = None  # the resident size after the last trim
        self._trimmed = clock()
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self.stats = {"trims": 0, "released": 0}

    def check(self) -> int:
        """Trim if it is time to (see the module doc); return the resident bytes given back."""
        now = self._resident()
        if now is None:
            return 0
        if self._lowest is None or now < self._lowest:
            self._lowest = now
        if self._after is None or now < self._after:
            self._after = now
        grown = now - self._after >= self._grow
        stale = now - self._lowest >= self._grow and self._clock() - self._trimmed >= self._settle
        if not (grown or stale) or not self._trim():
            return 0
        after = self._resident()
        after = now if after is None else after
        released = max(0, now - after)
        self.stats["trims"] += 1
        self.stats["released"] += released
        self._after = after
        self._trimmed = self._clock()
        return released

    def _run(self) -> None:
        while not self._halt.wait(self._every):
            self.check()

    def __enter__(self) -> HeapKeeper:
        if _TRIM is not None and self._thread is None:
            self._thread = threading.Thread(target=self._run, name="fleetlog-heap", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._halt.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
