"""What the player tells: its status while it plays, its summary at the end, its timing.

:class:`Status` is what the progress display and the Zenoh status publication show (JSON via
:meth:`Status.to_dict`); :class:`Summary` is the end report. :class:`Lateness` keeps the
publish-time error of paced entries in a fixed histogram, so a replay of any length measures
its p50/p99 in constant memory.
"""

from __future__ import annotations

import enum
from array import array
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Lateness", "State", "Status", "Summary", "VehicleCounts"]


class State(enum.Enum):
    """Where the player is."""

    PLAYING = "playing"
    PAUSED = "paused"
    #: held by PLAYBACK_CHOKE: the client's newest heartbeat is too old
    WAITING = "waiting for client"
    FINISHED = "finished"
    STOPPED = "stopped"


class Lateness:
    """A histogram of how late paced entries were published (10 us bins up to 100 ms).

    Args:
        bin_width: seconds per bin.
        bins: how many bins; later values go to an overflow count (their maximum is kept).
    """

    def __init__(self, bin_width: float = 10e-6, bins: int = 10_000) -> None:
        self._width = bin_width
        self._counts = array("Q", bytes(8 * (bins + 1)))
        self._bins = bins
        self.count = 0
        self.max = 0.0

    def add(self, seconds: float) -> None:
        """Record one entry published ``seconds`` after its due time (negative counts as 0)."""
        seconds = max(seconds, 0.0)
        self._counts[min(int(seconds / self._width), self._bins)] += 1
        self.count += 1
        self.max = max(self.max, seconds)

    def percentile(self, p: float) -> float | None:
        """Return the ``p``-th percentile (0-100) as the upper edge of its bin; None if empty."""
        if not self.count:
            return None
        rank = max(1, round(p / 100.0 * self.count))
        seen = 0
        for index, count in enumerate(self._counts):
            seen += count
            if seen >= rank:
                return self.max if index == self._bins else min((index + 1) * self._width, self.max)
        return self.max  # pragma: no cover - the counts add up to count


@dataclass
class VehicleCounts:
    """Per-vehicle counters.

    Attributes:
        published: entries published.
        filtered: entries left out by the source or variable filters.
        unplayable: entries that could not be published (a binary value whose bytes are
            missing from the blog).
    """

    published: int = 0
    filtered: int = 0
    unplayable: int = 0


@dataclass(frozen=True)
class Status:
    """A snapshot of the player.

    Attributes:
        state: playing, paused, waiting for client, finished or stopped.
        position: the playback position, absolute log time (seconds since the epoch).
        offset: the position in seconds from the replay's origin (the earliest LOGSTART).
        begin: where playback starts (and loops to), seconds from the origin.
        end: where it ends, seconds from the origin; None when unknown (a compressed log
            with no ``--to``).
        rate: the rate; None when playing as fast as possible.
        published: entries published so far.
        filtered: entries left out by the filters so far.
        loops: completed loops.
        vehicles: the vehicles published to.
    """

    state: State
    position: float
    offset: float
    begin: float
    end: float | None
    rate: float | None
    published: int
    filtered: int
    loops: int
    vehicles: tuple[str, ...]

    @property
    def fraction(self) -> float | None:
        """How far playback is between begin and end (0 ... 1), if the end is known."""
        if self.end is None:
            return None
        span = self.end - self.begin
        if span <= 0:
            return 1.0
        return min(max((self.offset - self.begin) / span, 0.0), 1.0)

    def to_dict(self) -> dict[str, Any]:
        """Return the status as JSON-ready data (what the status publication carries)."""
        return {
            "state": self.state.value,
            "position": self.position,
            "offset": round(self.offset, 6),
            "begin": round(self.begin, 6),
            "end": None if self.end is None else round(self.end, 6),
            "fraction": self.fraction,
            "rate": "fast" if self.rate is None else self.rate,
            "published": self.published,
            "filtered": self.filtered,
            "loops": self.loops,
            "vehicles": list(self.vehicles),
        }


@dataclass
class Summary:
    """The end report of a replay.

    Attributes:
        state: finished (the end was reached) or stopped (by a command or a signal).
        vehicles: counters per published vehicle.
        duplicates: re-delivered duplicates dropped.
        before_logstart: entries with negative offsets dropped.
        late: entries more out of order than the re-sort window (played at once).
        loops: completed loops.
        elapsed: wall seconds the replay ran.
        timing: how late paced entries were published.
        errors: the first few messages about unplayable entries.
        inputs: per input, ``(name, vehicle, published as, how the vehicle was found,
            truncated)``.
    """

    state: State
    vehicles: dict[str, VehicleCounts]
    duplicates: int = 0
    before_logstart: int = 0
    late: int = 0
    loops: int = 0
    elapsed: float = 0.0
    timing: Lateness = field(default_factory=Lateness)
    errors: list[str] = field(default_factory=list)
    inputs: list[tuple[str, str, str, str, bool]] = field(default_factory=list)

    @property
    def published(self) -> int:
        """Entries published, all vehicles."""
        return sum(c.published for c in self.vehicles.values())

    @property
    def filtered(self) -> int:
        """Entries left out by the filters, all vehicles."""
        return sum(c.filtered for c in self.vehicles.values())

    @property
    def unplayable(self) -> int:
        """Entries that could not be published, all vehicles."""
        return sum(c.unplayable for c in self.vehicles.values())

    def lines(self) -> list[str]:
        """Return the report as lines of text."""
        rate = self.published / self.elapsed if self.elapsed > 0 else 0.0
        out = [
            f"{self.state.value}: published {self.published} entries in {self.elapsed:.2f} s"
            f" ({rate:.0f}/s), skipped by filter {self.filtered}, duplicates dropped"
            f" {self.duplicates}, before LOGSTART {self.before_logstart}, out of order"
            f" {self.late}, unplayable {self.unplayable}, loops {self.loops}"
        ]
        for vehicle, counts in sorted(self.vehicles.items()):
            out.append(
                f"  {vehicle}: published {counts.published}, skipped by filter"
                f" {counts.filtered}, unplayable {counts.unplayable}"
            )
        p50 = self.timing.percentile(50)
        p99 = self.timing.percentile(99)
        if p50 is not None and p99 is not None:
            out.append(
                f"  timing: {self.timing.count} paced entries published p50 {p50 * 1e3:.3f} ms,"
                f" p99 {p99 * 1e3:.3f} ms, max {self.timing.max * 1e3:.3f} ms after their time"
            )
        for name, vehicle, published_as, how, truncated in self.inputs:
            alias = f", published as {published_as}" if published_as != vehicle else ""
            cut = " (its tail was cut; the entries before the cut were played)" if truncated else ""
            out.append(f"  input {name}: vehicle {vehicle} (from {how}){alias}{cut}")
        out.extend(f"  warning: {err}" for err in self.errors)
        return out
