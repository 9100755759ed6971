"""How to play: :class:`PlayOptions`, shared by the CLI, the replay service and the player."""

from __future__ import annotations

from dataclasses import dataclass, field

from fleetlog.errors import ReplayError
from fleetlog.replayer.control import check_rate
from fleetlog.replayer.filters import FilterSpec
from fleetlog.replayer.schedule import DEDUPE_MEMORY, DEFAULT_WINDOW

__all__ = ["MAX_CHOKE_TIME", "PlayOptions"]

#: uPlayBack's MAX_CHOKE_TIME: how old the client's heartbeat may be before playback waits.
MAX_CHOKE_TIME = 2.0


@dataclass(frozen=True)
class PlayOptions:
    """How to play.

    Attributes:
        rate: the rate (0.1 ... 100); None plays as fast as possible.
        start: where to start, seconds from the origin (the earliest LOGSTART); None: at
            the first entry.
        stop: where to stop, seconds from the origin; None: at the end.
        paused: start paused.
        loop: start again from ``start`` at the end.
        filters: which entries to publish.
        prefix: prepended to every vehicle name, to keep replayed data apart from live
            vehicles.
        window: each input's re-sort window, in records.
        dedupe: drop re-delivered duplicates.
        dedupe_memory: how many recent entries the duplicate check remembers.
        db_time: post PLAYBACK_DB_TIME.
        choke_time: PLAYBACK_CHOKE's limit on the heartbeat's age, seconds.
    """

    rate: float | None = 1.0
    start: float | None = None
    stop: float | None = None
    paused: bool = False
    loop: bool = False
    filters: FilterSpec = field(default_factory=FilterSpec)
    prefix: str = ""
    window: int = DEFAULT_WINDOW
    dedupe: bool = True
    dedupe_memory: int = DEDUPE_MEMORY
    db_time: bool = True
    choke_time: float = MAX_CHOKE_TIME

    def check(self) -> None:
        """Validate the options.

        Raises:
            ReplayError: a rate out of range, a stop before the start, a negative window.
        """
        if self.rate is not None:
            check_rate(self.rate)
        if self.start is not None and self.stop is not None and self.stop < self.start:
            msg = f"--to {self.stop:g} is before --from {self.start:g}"
            raise ReplayError(msg)
        if self.window < 0:
            msg = f"the sort window must be 0 or more entries, not {self.window}"
            raise ReplayError(msg)
