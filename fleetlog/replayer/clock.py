"""Clocks for the player: the real one, and a fake one that makes pacing tests instant.

The player needs three things from a clock: a monotonic time to pace entries against, the
wall-clock time that stamps each replayed message (uPlayBack stamps messages with
``MOOSTime()`` at replay, MOOS_FORMAT.md §8.2), and a way to wait until a deadline that a
control command or a PLAYBACK_CHOKE heartbeat can cut short.

:class:`RealClock` sleeps until about a millisecond before the deadline and then spins, because
``sleep`` alone overshoots by 50-100 us on a quiet machine and by milliseconds on a busy one.

:class:`FakeClock` is a small discrete-event simulator: waiting moves time forward at once,
and callbacks scheduled with :meth:`FakeClock.call_at` (a heartbeat arriving, a user pressing
pause) run at their instant and cut the wait short, as the real wake-up would.
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable
from typing import Protocol

from fleetlog.errors import ReplayError

__all__ = ["Clock", "FakeClock", "RealClock"]

#: How long before a deadline :class:`RealClock` stops sleeping and starts spinning.
SPIN_MARGIN = 0.001


class Clock(Protocol):
    """What the player needs from a clock."""

    def now(self) -> float:
        """Return monotonic seconds (for pacing; the origin is arbitrary)."""
        ...

    def wall(self) -> float:
        """Return seconds since the epoch (for message times and choke heartbeats)."""
        ...

    def wait(self, deadline: float | None) -> bool:
        """Wait until ``now() >= deadline`` (None: until woken); True if woken early."""
        ...

    def wake(self) -> None:
        """Cut the current or next :meth:`wait` short (thread-safe)."""
        ...


class RealClock:
    """The machine's clocks: ``time.monotonic`` for pacing, ``time.time`` for stamps.

    Args:
        spin_margin: seconds before a deadline when sleeping gives way to spinning.
    """

    def __init__(self, spin_margin: float = SPIN_MARGIN) -> None:
        self._event = threading.Event()
        self._margin = spin_margin

    #: ``time.monotonic()``, for pacing; ``time.time()``, for stamps (the C functions
    #: themselves: a replay as fast as possible asks once per entry)
    now = staticmethod(time.monotonic)
    wall = staticmethod(time.time)

    def wake(self) -> None:
        """Wake the waiting thread (from any thread)."""
        self._event.set()

    def wait(self, deadline: float | None) -> bool:
        """Sleep until a margin before ``deadline``, then spin; True if woken first."""
        event = self._event
        if deadline is None:
            event.wait()
            event.clear()
            return True
        remaining = deadline - time.monotonic()
        if remaining > self._margin and event.wait(remaining - self._margin):
            event.clear()
            return True
        # A pure spin: sleep(0) costs 130 us here and may hand the CPU to another process
        # for a whole time slice. Threads that want the GIL still get it at the switch
        # interval (:class:`fleetlog.replayer.service.ReplayService` shortens it).
        monotonic = time.monotonic
        is_set = event.is_set
        while monotonic() < deadline:
            if is_set():
                event.clear()
                return True
        return False


class FakeClock:
    """A clock whose time moves only when the player waits; for tests.

    Args:
        start: the initial monotonic time.
        epoch: the wall time that corresponds to monotonic time 0.

    Attributes:
        waits: every deadline passed to :meth:`wait`, in order (None for "until woken").
    """

    def __init__(self, start: float = 0.0, epoch: float = 1_800_000_000.0) -> None:
        self._now = start
        self._epoch = epoch
        self._events: list[tuple[float, int, Callable[[], None]]] = []
        self._seq = 0
        self._woken = False
        self.waits: list[float | None] = []

    def now(self) -> float:
        """Return the fake monotonic time."""
        return self._now

    def wall(self) -> float:
        """Return the fake wall time: ``epoch + now()``."""
        return self._epoch + self._now

    def advance(self, seconds: float) -> None:
        """Move time forward (running nothing); for work that takes time, like a publish."""
        self._now += seconds

    def call_at(self, when: float, action: Callable[[], None]) -> None:
        """Run ``action`` when fake time reaches ``when`` (during a wait)."""
        heapq.heappush(self._events, (when, self._seq, action))
        self._seq += 1

    def wake(self) -> None:
        """Make the current or next wait return at once."""
        self._woken = True

    def wait(self, deadline: float | None) -> bool:
        """Jump to ``deadline``, or to the first scheduled action before it and run it.

        Raises:
            ReplayError: an endless wait with nothing scheduled (the test would hang).
        """
        self.waits.append(deadline)
        if self._woken:
            self._woken = False
            return True
        if self._events and (deadline is None or self._events[0][0] < deadline):
            when, _, action = heapq.heappop(self._events)
            self._now = max(self._now, when)
            action()
            self._woken = False
            return True
        if deadline is None:
            msg = "the player waits forever and nothing is scheduled on the fake clock"
            raise ReplayError(msg)
        self._now = max(self._now, deadline)
        return False
