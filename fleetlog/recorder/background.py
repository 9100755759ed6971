"""File work the recording thread must not wait for, run in order in a thread of its own.

fsync can take tens or hundreds of milliseconds on the SD cards and eMMC vehicles carry, and
the session metadata is written with two of them (the file, then its directory). The drain
thread hands such work here and carries on; jobs run one at a time in the order given, so
a session's last metadata is always written after its earlier versions.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

__all__ = ["Background", "BackgroundWriter", "inline"]

#: runs file work the drain thread must not wait for (fsync, metadata) in order, elsewhere
Background = Callable[[Callable[[], None]], None]


def inline(job: Callable[[], None]) -> None:
    """Run ``job`` now (the default: tests and embedding without a background thread)."""
    job()


class BackgroundWriter:
    """Runs jobs in order in one thread.

    Args:
        on_error: told of a job that raised (jobs report their own expected failures).
    """

    def __init__(self, on_error: Callable[[str], None]) -> None:
        self._queue: queue.SimpleQueue[Callable[[], None] | None] = queue.SimpleQueue()
        self._on_error = on_error
        self._thread = threading.Thread(target=self._run, name="fleetlog-background", daemon=True)
        self._thread.start()

    def submit(self, job: Callable[[], None]) -> None:
        """Queue ``job`` (any thread)."""
        self._queue.put(job)

    def backlog(self) -> int:
        """Return how many jobs wait."""
        return self._queue.qsize()

    def _run(self) -> None:
        while True:
            job = self._queue.get()
            if job is None:
                return
            try:
                job()
            except Exception as err:  # the thread must outlive any one job
                self._on_error(f"background file work failed: {err}")

    def close(self, timeout: float = 30.0) -> bool:
        """Run what is queued, then stop; return False if that took longer than ``timeout``."""
        self._queue.put(None)
        self._thread.join(timeout)
        return not self._thread.is_alive()
