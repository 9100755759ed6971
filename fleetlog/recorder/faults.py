"""When the disk fails under the recorder: count, mark, fall back, and open again.

:class:`StorageFaults` is the part of :class:`~fleetlog.recorder.sessions.SessionKeeping`
that handles a failed write: pLogger's fallback (the working directory), a session
directory removed while recording, a full or read-only file system and the automatic new
session once writing works again. Every loss is counted by variable and marked
(``PLOGGER_GAP``, docs/compat.md). Opening and closing sessions is
:mod:`fleetlog.recorder.sessions`; keeping their metadata current,
:mod:`fleetlog.recorder.metadata`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import FleetlogError, StorageError
from fleetlog.recorder.losses import LossLedger, reason_of
from fleetlog.recorder.stats import RecorderStats
from fleetlog.storage.session import SessionWriter

__all__ = ["MIN_FREE_BYTES", "RETRY_FIRST", "RETRY_MAX", "Health", "StorageFaults"]

#: with no session open, opening one is retried after this long (doubling up to the maximum)
RETRY_FIRST = 1.0
RETRY_MAX = 8.0
#: a file system with less free space than this is not worth a retry yet
MIN_FREE_BYTES = 1 << 20


@dataclass
class Health:
    """How writing goes: failures, retries, lag, fsync (cold state, kept off the Recorder).

    The Recorder itself keeps at most 30 attributes: CPython 3.11 keeps an instance's
    attributes inline (fast ``self.x`` in the hot path) only up to that many; past it every
    attribute read in :meth:`Recorder.handle` got 15 % slower (measured, docs/reliability.md).
    """

    #: why no session is open after a failure (None while writing works)
    broken: str | None = None
    retry_at: float = 0.0
    retry_wait: float = 1.0
    #: the longest a line waited between arrival and the OS, this status period and the last
    lag: float = 0.0
    last_lag: float = 0.0
    #: fsync: when the last one finished (epoch), the longest it took, the next, one running
    synced_at: float | None = None
    max_fsync: float = 0.0
    sync_due: float = 0.0
    sync_running: bool = False
    #: lines reached the OS since the last fsync began (an idle session is not synced)
    unsynced: bool = True
    #: when losses were last marked in the alog
    gaps_at: float = 0.0
    #: samples the transport may hold before the recorder takes them (set by the service)
    queue: int | None = None
    #: the open session is the recorder's own fallback after a write error
    in_fallback: bool = False
    #: keys already reported as naming no variable
    unreadable: set[str] = field(default_factory=set)
    #: samples lost on the way per publisher (its Zenoh id), not yet on MOOS_DEBUG
    missed: dict[str, int] = field(default_factory=dict)


class StorageFaults:
    """The failure half of the session keeping (a mixin: the Recorder sets what it uses)."""

    # What it uses of the Recorder (set by Recorder.__init__).
    session: SessionWriter | None
    stats: RecorderStats
    logstart: float
    losses: LossLedger
    _clock: Callable[[], float]
    _h: Health
    _unflushed_since: float | None

    def debug(self, text: str) -> None:
        """Post a MOOS_DEBUG message (the Recorder's)."""
        raise NotImplementedError

    def _open_session(self, path: str | None = None) -> SessionWriter:
        """Open a new session (the session keeping's)."""
        raise NotImplementedError

    def _finish(self, session: SessionWriter) -> None:
        """Sync a closed session and write its last metadata (the session keeping's)."""
        raise NotImplementedError

    def _forget_meta(self) -> None:
        """Drop the open session's metadata: nowhere to write it (the session keeping's)."""
        raise NotImplementedError

    @property
    def log_root(self) -> Path:
        """The directory the sessions are created in (the session keeping's)."""
        raise NotImplementedError

    def _resume_free(self) -> int:
        """The free space a new session needs after a failure (the disk guard's)."""
        return MIN_FREE_BYTES

    def _storage_failed(self, err: FleetlogError, *, lost: int, fallback: bool = True) -> None:
        """Count, report and fall back: a full or read-only disk must not stop the recorder.

        Args:
            err: what went wrong.
            lost: samples in hand that were not written, besides the lines the session's
                streams count as never written (those are counted here, by variable).
            fallback: drop the broken session and try pLogger's fallback (the working
                directory); False when the session is being closed anyway (it is passed
                as ``self.session`` is already cleared, see :meth:`_close_session`).
        """
        stats = self.stats
        reason = reason_of(err)
        session = self.session
        now = self._clock()
        if session is not None and fallback:
            self.session = None
            self._unflushed_since = None
            with contextlib.suppress(StorageError):
                session.close()  # writes what it can of the other streams
            self._count_unwritten(session, reason, now)
        root = session.root if session is not None else ""
        stats.lost += lost
        stats.write_errors += 1
        first = stats.last_error != str(err)
        stats.last_error = str(err)
        self.losses.add(reason, lost, now, session=root)
        if first:
            self.debug(f"write error, samples are being lost: {err}")
        if session is None or not fallback:
            return
        self._finish(session)
        if session.fallback or self._h.in_fallback or self._open_fallback() is None:
            # Nothing left to fall back to: samples are counted as lost, and a new session
            # opens by itself once the disk takes writes again (or at a LOGGER_RESTART).
            self._set_broken(reason, now)

    def _count_unwritten(self, session: SessionWriter, reason: str, now: float) -> None:
        """Count as lost, by variable, the lines a failed session never wrote."""
        for name, count in session.take_unwritten().items():
            self.stats.lost += count
            self.losses.add(reason, count, now, name=name, session=session.root)

    def _set_broken(self, reason: str, now: float) -> None:
        self._h.broken = reason
        self._h.retry_at = now + self._h.retry_wait
        self.debug(
            f"no session is open ({reason}): samples are being lost until writing works again"
        )

    def _session_removed(self, session: SessionWriter, now: float) -> None:
        """The session's directory (or its alog) was removed while recording: carry on.

        A new session opens at once with the same LOGSTART, so the lines not yet handed to
        the OS move into it unchanged (what the OS had went with the directory: the
        operator removed it). A binary line cannot move (its record went to the removed
        blog): it is counted lost.
        """
        stats = self.stats
        stats.write_errors += 1
        stats.last_error = f"the session directory {session.directory} was removed"
        pending = session.take_pending()
        self.session = None
        self._unflushed_since = None
        with contextlib.suppress(StorageError):
            session.close()
        self._forget_meta()  # nowhere to write its last version
        if session.lock is not None:
            session.lock.release()
        lost = 0

        def drop(line: str) -> None:
            nonlocal lost
            lost += 1
            fields = line.split(None, 2)
            name = fields[1] if len(fields) > 1 else None
            self.losses.add("removed", 1, now, name=name, session=session.root)

        samples = ("alog", "xlog")  # one line per sample; the ylog repeats alog lines
        for kind in samples:
            kept = []
            for line in pending.get(kind, ()):
                if "<MOOS_BINARY>" in line:
                    drop(line)
                else:
                    kept.append(line)
            pending[kind] = kept
        self.losses.add("removed", 0, now, session=session.root, always=True)
        try:
            new: SessionWriter | None = self._open_session()
        except StorageError as err:
            new = None
            stats.last_error = str(err)
        moved = 0
        for kind, lines in pending.items():
            stream = None if new is None else getattr(new, kind)
            for line in lines:
                if stream is not None:
                    stream.write(line)
                    moved += 1
                elif kind in samples:
                    drop(line)
        stats.lost += lost
        if moved and self._unflushed_since is None:
            self._unflushed_since = now
        self.debug(
            f"the session directory {session.directory} was removed while recording: "
            f"now logging to {new.directory if new else 'nothing'} ({lost} samples lost)"
        )
        if new is None:
            self._set_broken("removed", now)

    def _retry(self, now: float) -> None:
        """With no session open after a failure: open one if the disk takes writes again.

        The file system is asked every second (statvfs: read-only? space?); an attempt that
        still fails waits twice as long before the next, up to 8 s.
        """
        self._h.retry_at = now + RETRY_FIRST
        if not _writable(self.log_root, self._resume_free()):
            return
        self.logstart = now
        try:
            session = self._open_session()
        except StorageError as err:
            self.stats.last_error = str(err)
            self._h.retry_wait = min(self._h.retry_wait * 2, RETRY_MAX)
            self._h.retry_at = now + self._h.retry_wait
            return
        self.debug(f"writing works again: now logging to {session.directory}")

    def _open_fallback(self) -> SessionWriter | None:
        """Open a session in the working directory (pLogger's fallback) and announce it."""
        try:
            session = self._open_session(path=".")
        except StorageError as err:
            self.stats.last_error = str(err)
            self.debug(f"fallback failed too, samples are being lost: {err}")
            return None
        self.debug(f"now logging to the fallback {session.directory}")
        return session


def _writable(path: Path, need: int = MIN_FREE_BYTES) -> bool:
    """Return True unless ``path``'s file system is read-only or has less than ``need`` free.

    A directory that no longer exists may be created again (or its fallback used): True.
    """
    try:
        st = os.statvfs(path)
    except OSError:
        return True
    if st.f_flag & os.ST_RDONLY:
        return False
    return st.f_bavail * st.f_frsize >= need
