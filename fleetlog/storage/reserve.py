"""A free-space reserve on the shore: downloads stop before they fill the disk.

A shore archive collects every vehicle's sessions; a full disk there fails every write at
once, and what else runs on that machine with it. A vehicle's listing is also a peer's
word: a file it says holds a petabyte must not be pulled until the disk is full. Each
download asks :meth:`DiskReserve.check` before it writes; the file system is looked at
again every half second or 16 MiB, so the cost per range is a subtraction.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.moos.units import human_size

__all__ = ["DEFAULT_SHORE_RESERVE", "DiskReserve"]

#: free space a shore download leaves by default (``--min-free-disk``)
DEFAULT_SHORE_RESERVE = 512 << 20
_LOOK_EVERY = 0.5
_LOOK_AFTER = 16 << 20


class DiskReserve:
    """Keeps ``reserve`` bytes free on the file system of ``directory`` while writing there.

    Args:
        directory: where the downloads go (it need not exist yet: its nearest existing
            parent is looked at).
        reserve: bytes to leave free; 0 turns the check off.
        clock: a monotonic clock (tests pass their own).
    """

    def __init__(
        self, directory: Path, reserve: int, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.directory = directory
        self.reserve = reserve
        self._clock = clock
        self._free: int | None = None
        self._looked = float("-inf")
        self._since = 0

    def _look(self) -> int | None:
        path = self.directory
        while not path.exists() and path.parent != path:
            path = path.parent
        try:
            st = os.statvfs(path)
        except OSError:
            return None  # cannot tell: the writes themselves will say
        return st.f_bavail * st.f_frsize

    def check(self, incoming: int, what: str = "", *, writing: bool = True) -> None:
        """Raise if writing ``incoming`` more bytes would leave less than the reserve.

        ``writing``: the bytes are written now (counted until the next look); False asks
        ahead of a transfer without counting what it has not written yet.

        Raises:
            StorageError: it would; the message says how much is free and how to go on.
        """
        if self.reserve <= 0:
            return
        now = self._clock()
        if (
            self._free is None
            or now - self._looked >= _LOOK_EVERY
            or self._since + incoming >= _LOOK_AFTER
        ):
            self._free, self._looked, self._since = self._look(), now, 0
        if self._free is None:
            return
        left = self._free - self._since - incoming
        if left < self.reserve:
            free = max(0, self._free - self._since)
            about = f" for {what}" if what else ""
            msg = (
                f"{self.directory} has {human_size(free)} free and {human_size(incoming)}"
                f" more{about} would leave less than the {human_size(self.reserve)} kept free"
                " (--min-free-disk); free space there (or lower --min-free-disk) and run again:"
                " what is fetched so far is kept"
            )
            raise StorageError(msg)
        if writing:
            self._since += incoming
