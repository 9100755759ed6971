"""Snapshot mode's memory: the last N seconds of samples, and each variable's latest older value.

In snapshot mode (``SnapshotSeconds``, docs/compat.md) the recorder writes nothing until a
SNAPSHOT; every sample it would log goes into a :class:`SnapshotRing` instead. A sample
leaves the ring when it is older than the window (it then becomes its variable's *latest
older value*, which replaces the one before) or, before that, when the ring would hold more
than ``SnapshotMemory`` bytes: an *eviction*, counted, because a snapshot taken now misses it.

A SNAPSHOT does not empty the ring: :meth:`SnapshotRing.begin` returns the latest older
values and the sequence number of the oldest sample in the window, and the recorder writes
from that number on (:meth:`SnapshotRing.since`) while samples keep arriving, so a snapshot
session holds everything from its window to its end exactly once and in arrival order, and
each session is whole on its own (a later snapshot may repeat samples an earlier one holds).

Samples are sized by an estimate of what CPython holds for them (the message, its strings,
the ring's tuple), on the high side, so the ring's real memory stays under its bound
(bench/snapshot.py measures it).
"""

from __future__ import annotations

import collections
import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from fleetlog.wire.message import MoosMessage

__all__ = ["MAX_VARIABLES", "Held", "SnapshotRing", "sample_size"]

#: variables whose latest older value is kept (as many as the engine keeps state for)
MAX_VARIABLES = 65536
#: bytes a held sample costs besides its strings' characters: the ring's tuple and slot,
#: the message object, its two floats and the arrival time, and the strings' headers
_OVERHEAD = 480

#: a held sample: arrival time (recorder clock), time stamp (after the skew rule), message
Held = tuple[float, float, MoosMessage]


def sample_size(msg: MoosMessage) -> int:
    """Return the bytes a held sample is counted as (an estimate on the high side)."""
    value = msg.value
    size = _OVERHEAD + len(msg.name) + len(msg.source) + len(msg.aux) + len(msg.community)
    if isinstance(value, float):
        return size
    if isinstance(value, str) and not value.isascii():
        return size + 4 * len(value)  # CPython keeps up to 4 bytes a character
    return size + len(value)


@dataclass
class RingCounts:
    """What the ring did; never reset."""

    #: samples put in the ring
    held: int = 0
    #: samples pushed out by the memory bound before they were ``seconds`` old
    evicted: int = 0
    #: samples that left the window without being written (they may still be written as
    #: their variable's latest older value)
    unsaved: int = 0


class SnapshotRing:
    """The last ``seconds`` of samples, bounded by ``memory`` bytes, and older values.

    Args:
        seconds: the window (arrival times, the recorder's clock).
        memory: the most bytes the samples and the older values are counted as.
    """

    def __init__(self, seconds: float, memory: int) -> None:
        self.seconds = seconds
        self.memory = memory
        self._ring: collections.deque[Held] = collections.deque()
        #: each variable's latest older value (insertion order: least recently replaced first)
        self._older: dict[str, Held] = {}
        self.bytes = 0
        self.counts = RingCounts()
        #: the sequence number of the ring's oldest sample (numbers count every sample held)
        self.first = 0
        #: samples up to this sequence number were written in a snapshot session
        self.written = 0
        #: a snapshot is writing from this sequence number: those samples do not age out
        #: (the memory bound still evicts them)
        self.pin: int | None = None

    def __len__(self) -> int:
        return len(self._ring)

    @property
    def variables(self) -> int:
        """Variables with a latest older value."""
        return len(self._older)

    def oldest(self) -> float | None:
        """The arrival time of the oldest sample in the ring."""
        return self._ring[0][0] if self._ring else None

    def add(self, arrival: float, stamp: float, msg: MoosMessage) -> None:
        """Hold one sample (arrival times never go back: the recorder's clock)."""
        ring = self._ring
        ring.append((arrival, stamp, msg))
        self.counts.held += 1
        self.bytes += sample_size(msg)
        horizon = arrival - self.seconds
        if ring[0][0] < horizon:
            self._expire(horizon)
        if self.bytes > self.memory:
            self._evict()

    def expire(self, now: float) -> None:
        """Let samples older than the window leave the ring (call before reading it)."""
        horizon = now - self.seconds
        if self._ring and self._ring[0][0] < horizon:
            self._expire(horizon)

    def _expire(self, horizon: float) -> None:
        ring = self._ring
        pin = self.pin
        while ring and ring[0][0] < horizon and (pin is None or self.first < pin):
            self._leave(ring.popleft())

    def _evict(self) -> None:
        ring = self._ring
        while self.bytes > self.memory and ring:
            self._leave(ring.popleft())
            self.counts.evicted += 1
        # What is left is older values alone: the least recently replaced go first.
        older = self._older
        while self.bytes > self.memory and older:
            name = next(iter(older))
            self.bytes -= sample_size(older.pop(name)[2])

    def _leave(self, held: Held) -> None:
        """A sample leaves the ring: it becomes its variable's latest older value."""
        if self.first >= self.written:
            self.counts.unsaved += 1
        self.first += 1
        msg = held[2]
        older = self._older
        previous = older.pop(msg.name, None)
        if previous is not None:
            self.bytes -= sample_size(previous[2])
        elif len(older) >= MAX_VARIABLES:
            name = next(iter(older))
            self.bytes -= sample_size(older.pop(name)[2])
        older[msg.name] = held

    def begin(self, now: float) -> tuple[list[Held], int]:
        """Start a snapshot at ``now``: the latest older values, and where the window starts.

        Returns:
            The latest older value of each variable, in time stamp order, and the sequence
            number of the oldest sample of the window (what :meth:`since` takes).
        """
        self.expire(now)
        older = sorted(self._older.values(), key=lambda held: (held[1], held[0]))
        return older, self.first

    def end(self) -> int:
        """The sequence number after the newest sample held."""
        return self.first + len(self._ring)

    def since(self, seq: int, count: int) -> Iterator[tuple[int, Held]]:
        """Yield up to ``count`` samples from sequence number ``seq`` (clipped to the ring).

        A ``seq`` older than the ring's oldest sample starts at the oldest: the samples in
        between were evicted before they were written (the caller counts them).
        """
        start = max(seq, self.first)
        offset = start - self.first
        ring = self._ring
        tail = len(ring) - offset
        # A deque is walked from one end: from the nearer one (while a snapshot records on,
        # the samples still to write are the newest few).
        if offset <= tail:
            items = list(itertools.islice(ring, offset, offset + count))
        else:
            items = list(itertools.islice(reversed(ring), max(tail - count, 0), tail))
            items.reverse()
        for i, held in enumerate(items):
            yield start + i, held

    def min_stamp(self, seq: int) -> float | None:
        """The earliest time stamp of the samples from ``seq`` on."""
        offset = max(seq - self.first, 0)
        stamps = [held[1] for held in itertools.islice(self._ring, offset, None)]
        return min(stamps) if stamps else None

    def status(self, now: float) -> dict[str, Any]:
        """The ring's state for the status reply."""
        oldest = self.oldest()
        return {
            "seconds": self.seconds,
            "memory": self.memory,
            "samples": len(self._ring),
            "bytes": self.bytes,
            "span": 0.0 if oldest is None else max(now - oldest, 0.0),
            "older_values": len(self._older),
            "held": self.counts.held,
            "evicted": self.counts.evicted,
            "unsaved": self.counts.unsaved,
        }
