"""Which files are being fetched right now, seen by every process on the vehicle.

Retention must never delete a session while someone downloads it (docs/wire.md, "Session
metadata"; ``../shared/DESIGN_NOTES.md``). The process that serves a file may not be the one
that deletes (a ``fleetlog serve --standby`` beside a ``--no-serve`` recorder), so the signal
is a kernel lock, not a table in memory: while a file is being fetched its server holds a
*shared* ``flock`` on it (:class:`FileLeases`), and retention deletes a session only under an
*exclusive* ``flock`` of each of its files (:func:`exclusive_files`), which it cannot take
while any lease is held. The kernel drops the locks however the server dies.

A lease starts with the first range of a file served, is renewed by every range, and ends

* when a range reaches the end of the file of a complete session (the fetch has it all),
* when the fetch asks for the digest of the file of a complete session (it verifies what it
  has: a fetch that goes on takes a new lease with its next range), or
* :data:`LEASE_SECONDS` after the last range (a fetch whose link was cut retries for 30 s by
  default; a client that never comes back does not pin the session for ever).

So a session a collector has just fetched whole is free to be pruned at once, and one an
operator is half-way through is not.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import stat
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

__all__ = ["LEASE_SECONDS", "MAX_LEASES", "FileLeases", "exclusive_files"]

#: how long a lease outlives the last range served
LEASE_SECONDS = 120.0
#: leases held at most (each is an open descriptor); the oldest is dropped beyond it
MAX_LEASES = 256


class FileLeases:
    """Shared ``flock`` leases on the files being fetched (the server's side).

    Thread-safe. Args:
        lease: seconds a lease outlives the last range served.
        limit: leases held at most.
        clock: monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        lease: float = LEASE_SECONDS,
        limit: int = MAX_LEASES,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.lease = lease
        self.limit = max(1, limit)
        self._clock = clock
        self._lock = threading.Lock()
        #: path → (descriptor, expiry, (device, inode)); oldest renewal first
        self._held: OrderedDict[Path, tuple[int, float, tuple[int, int]]] = OrderedDict()

    def served(self, path: Path, st: os.stat_result, *, finished: bool) -> None:
        """A range of ``path`` (whose ``stat`` is ``st``) was served.

        Args:
            path: the file.
            st: its stat when the range was read (the lease is on that inode).
            finished: the range reached the end of a file that no longer grows: the lease
                ends now.
        """
        identity = (st.st_dev, st.st_ino)
        now = self._clock()
        with self._lock:
            self._expire(now)
            held = self._held.pop(path, None)
            if held is not None and (finished or held[2] != identity):
                # Done, or the name is another file now (replaced, as the session metadata
                # is while it is open): the old lease goes.
                _close(held[0])
                held = None
            if finished:
                return
            if held is None:
                fd = _lock_shared(path, identity)
                if fd is None:
                    return  # being deleted, or gone: nothing to protect
                held = (fd, 0.0, identity)
            self._held[path] = (held[0], now + self.lease, identity)
            while len(self._held) > self.limit:
                _, (old, _, _) = self._held.popitem(last=False)
                _close(old)

    def _expire(self, now: float) -> None:
        for path in [p for p, (_, until, _) in self._held.items() if until <= now]:
            fd, _, _ = self._held.pop(path)
            _close(fd)

    def paths(self) -> list[Path]:
        """Return the files under lease now."""
        with self._lock:
            self._expire(self._clock())
            return list(self._held)

    def sessions(self, log_root: Path) -> set[str]:
        """Return the names of the sessions directly under ``log_root`` with a file under lease."""
        return {p.parent.name for p in self.paths() if p.parent.parent == log_root}

    def close(self) -> None:
        """Drop every lease."""
        with self._lock:
            for fd, _, _ in self._held.values():
                _close(fd)
            self._held.clear()


def _close(fd: int) -> None:
    with contextlib.suppress(OSError):
        os.close(fd)


def _lock_shared(path: Path, key: tuple[int, int]) -> int | None:
    """Open ``path`` and take a shared lock on it, if it is still the inode ``key``."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if (st.st_dev, st.st_ino) != key or not stat.S_ISREG(st.st_mode):
            _close(fd)
            return None
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        _close(fd)  # held exclusively: retention is deleting it
        return None
    return fd


@contextlib.contextmanager
def exclusive_files(paths: Iterable[Path]) -> Iterator[bool]:
    """Hold an exclusive ``flock`` on every file of ``paths`` for the ``with`` block.

    Yields True when every lock was taken (no file is being fetched), False when one is held
    elsewhere (a lease: a fetch in flight); the locks taken are released at the end either way.
    A file that vanished meanwhile needs no lock; one whose file system has no ``flock`` is
    taken as free (nothing could hold a lease on it either).
    """
    fds: list[int] = []
    free = True
    try:
        for path in paths:
            try:
                fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
            except OSError:
                continue
            fds.append(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                free = False
                break
            except OSError:
                continue  # no flock on this file system
        yield free
    finally:
        for fd in fds:
            _close(fd)
