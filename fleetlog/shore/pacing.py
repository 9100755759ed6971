"""How fast a download may go: rate caps shared between transfers, and a link-friendly window.

**Rate caps** (:class:`RateLimit`): a fetch waits before each range until the bytes it asks
for fit under every cap it is given; one cap object shared by several transfers caps their
sum (``collect --max-rate`` per vehicle, ``--max-total-rate`` over the fleet).

**Pacing** (:class:`Pacer`) decides how many bytes of ranges are in flight and how large
each range is. :class:`FixedPacer` is what ``fetch`` does on a LAN: 8 ranges of 1 MiB.
Over a radio link that is 8 MiB queued in front of every command: at 1 Mbit/s a minute.
Zenoh's background priority lets commands overtake ranges still in the vehicle's Zenoh
queues, but not the bytes already handed to TCP and queued in the link (a radio modem's
buffer, a router's queue), which is where a busy link keeps them.

:class:`LinkPacer` keeps that queue short, the way LEDBAT (RFC 6817) does for background
transfers: it measures each range's round trip, takes the smallest recent one as the
link's base delay, and grows the window while the extra delay stays under a target
(100 ms), shrinking it when the queue grows past it. A range's size follows the measured
rate (about 50 ms of the link, 16 KiB to 1 MiB), so one range never holds the link for
long. On a fast link the window reaches the same 8 MiB cap as :class:`FixedPacer`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Protocol

__all__ = ["FixedPacer", "LinkPacer", "Pacer", "RateLimit"]

KIB = 1 << 10
MIB = 1 << 20


class RateLimit:
    """A cap of ``rate`` bytes per second, shared by every transfer given it (thread-safe).

    Args:
        rate: bytes per second; None or 0 for no cap.
        burst: seconds' worth of bytes that may go at once after a pause.
        clock: monotonic seconds.
        sleep: waits (tests pass their own).
    """

    def __init__(
        self,
        rate: float | None,
        *,
        burst: float = 0.25,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.rate = rate or None
        self.burst = burst
        self._clock = clock
        self._sleep = sleep
        self._lock = threading.Lock()
        self._next = clock()

    def wait(self, amount: int) -> None:
        """Wait until ``amount`` more bytes fit under the cap, and count them."""
        if self.rate is None:
            return
        with self._lock:
            now = self._clock()
            start = max(self._next, now - self.burst)
            self._next = start + amount / self.rate
            delay = start - now
        if delay > 0:
            self._sleep(delay)


class Pacer(Protocol):
    """Decides the ranges of one transfer: their size and how many bytes are in flight."""

    def chunk(self) -> int:
        """Return the size of the next range."""
        ...

    def room(self, inflight: int, count: int) -> bool:
        """Return True if another range may go out with ``inflight`` bytes in ``count`` ranges."""
        ...

    def arrived(self, length: int, seconds: float) -> None:
        """A range of ``length`` bytes came back ``seconds`` after it was asked for."""
        ...


class FixedPacer:
    """``window`` ranges of ``chunk`` bytes in flight, whatever the link (fetch's default)."""

    def __init__(self, window: int = 8, chunk: int = MIB) -> None:
        self.window = max(1, window)
        self._chunk = chunk

    def chunk(self) -> int:
        """The fixed range size."""
        return self._chunk

    def room(self, inflight: int, count: int) -> bool:
        """Fewer than ``window`` ranges are in flight."""
        return count < self.window

    def arrived(self, length: int, seconds: float) -> None:
        """Nothing to learn."""


class LinkPacer:
    """A delay-based window that keeps the link's queue short (see the module docstring).

    Thread-safe; one pacer may serve every transfer of one vehicle (they share its link).

    Args:
        target: the extra delay (seconds) the transfer may add to the link's round trip.
        min_chunk: the smallest range.
        max_chunk: the largest range.
        max_window: bytes in flight at most.
        clock: monotonic seconds.
    """

    #: how long the smallest round trip seen stays the base delay
    BASE_MEMORY = 600.0
    #: round trips the current delay is the smallest of (a filter against noise)
    RECENT = 4
    #: the share of a second of the measured rate one range holds
    RANGE_SECONDS = 0.05

    def __init__(
        self,
        *,
        target: float = 0.1,
        min_chunk: int = 4 * KIB,
        max_chunk: int = MIB,
        max_window: int = 8 * MIB,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.target = target
        self.min_chunk = min_chunk
        self.max_chunk = max_chunk
        self.max_window = max_window
        self._clock = clock
        self._lock = threading.Lock()
        self._chunk = min_chunk
        self.window = float(2 * min_chunk)
        self._slow_start = True
        self._bases: deque[tuple[float, float]] = deque()  # (when, round trip)
        self._recent: deque[float] = deque(maxlen=self.RECENT)
        self._received: deque[tuple[float, int]] = deque()  # (when, bytes): the rate
        self._chunk_at = clock()

    def chunk(self) -> int:
        """The range size for the link's current rate."""
        with self._lock:
            return self._chunk

    def room(self, inflight: int, count: int) -> bool:
        """Another range fits in the window (one is always allowed)."""
        with self._lock:
            return count == 0 or inflight + self._chunk <= self.window

    @property
    def rate(self) -> float:
        """Bytes per second received over the last two seconds."""
        with self._lock:
            return self._rate(self._clock())

    def _rate(self, now: float) -> float:
        while self._received and self._received[0][0] < now - 2.0:
            self._received.popleft()
        if not self._received:
            return 0.0
        span = max(now - self._received[0][0], 0.25)
        return sum(n for _, n in self._received) / span

    def arrived(self, length: int, seconds: float) -> None:
        """Learn from one range's round trip; grow or shrink the window."""
        with self._lock:
            now = self._clock()
            self._received.append((now, length))
            self._recent.append(seconds)
            while self._bases and (
                self._bases[0][0] < now - self.BASE_MEMORY or self._bases[-1][1] >= seconds
            ):
                # keep a queue of increasing round trips: its head is the smallest recent one
                if self._bases[-1][1] >= seconds:
                    self._bases.pop()
                else:
                    self._bases.popleft()
            self._bases.append((now, seconds))
            base = self._bases[0][1]
            queued = min(self._recent) - base
            off = (self.target - queued) / self.target
            chunk = self._chunk
            if self._slow_start and queued < self.target / 2:
                self.window += length  # doubles every round trip
                # ranges grow with the window meanwhile: a LAN is at full speed in a few
                # round trips, a radio link's slow start ends while they are still small
                while self._chunk * 4 <= self.window and self._chunk < self.max_chunk:
                    self._chunk *= 2
            else:
                self._slow_start = False
                # LEDBAT: one range more per window's worth of replies when on target,
                # at most half the window less per round trip when far over it
                step = max(off, -1.0) * length * chunk / max(self.window, chunk)
                self.window += step
            self.window = min(max(self.window, float(chunk)), float(self.max_window))
            self._resize(now)

    def _resize(self, now: float) -> None:
        # A range holds the link about RANGE_SECONDS; re-sized at most every 0.25 s. The
        # base delay is kept: a range's round trip includes its own bytes, so a larger range
        # looks queued by at most RANGE_SECONDS more, which errs on the side of the link (a
        # base measured afresh while the queue is full would let it grow for good).
        if now - self._chunk_at < 0.25:
            return
        self._chunk_at = now
        want = self._rate(now) * self.RANGE_SECONDS
        size = self.min_chunk
        while size < want and size < self.max_chunk:
            size *= 2
        size = min(size, self.max_chunk)
        if size != self._chunk:
            self._chunk = size
            self.window = max(self.window, float(size))
