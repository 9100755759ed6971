"""The disk guard and retention, the recorder's half: when to stop writing, what to remove.

``MinFreeDisk`` (docs/compat.md, "Disk guard and retention"): once a second the recorder asks
the log root's file system how much space is left. Below the bound it closes its session and
writes nothing more: MOOS_DEBUG and the status say why, what arrives meanwhile is counted lost
(reason ``low-disk``, marked as a gap in the next session), and writing resumes in a new
session once the free space is back above the bound plus a margin (:data:`MARGIN`, so a
disk at the edge does not open a session a second) — the same path the recorder takes after
a full disk (:mod:`fleetlog.recorder.faults`, docs/reliability.md §1).

Retention: ``KeepSessions`` and ``MaxLogSize`` bound what the log root keeps, and the guard
frees space by removing sessions the shore has acknowledged. The policies here only choose;
:mod:`fleetlog.storage.retention` is the only code that deletes, never the current session
nor one being fetched, acknowledged sessions first. A retention pass hashes files (an
acknowledgement is checked against the files' sha256), so it runs in a thread of its own, one
pass at a time, never on the recording thread, and never holds up the fsync and metadata
writes of the background writer.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlog.errors import StorageError
from fleetlog.moos.keep_settings import DiskSettings
from fleetlog.recorder.faults import MIN_FREE_BYTES
from fleetlog.recorder.modes import ModeKeeping
from fleetlog.storage import retention
from fleetlog.storage.retention import RetentionView, StoredSession
from fleetlog.storage.session import SessionWriter

if TYPE_CHECKING:
    from fleetlog.recorder.control import CommandHandler

__all__ = [
    "CHECK_INTERVAL",
    "MARGIN",
    "RETENTION_INTERVAL",
    "DiskGuard",
    "DiskKeeping",
    "FreeSpace",
    "KeepSessions",
    "MaxLogSize",
    "free_bytes",
]

#: how often the free space is checked; at every tick of the drain loop once it is less
#: than twice the resume level (statvfs costs a few µs; a fast writer must not outrun it)
CHECK_INTERVAL = 1.0
#: retention runs at least this often while a bound is set (and after every new session)
RETENTION_INTERVAL = 60.0
#: writing resumes above MinFreeDisk plus a tenth of it (at least 1 MiB)
MARGIN = 0.1
#: a stop's reason (the gap reason of what is lost meanwhile)
LOW_DISK = "low-disk"


def free_bytes(path: Path) -> int | None:
    """Return the bytes an unprivileged writer may still use under ``path`` (None: unknown)."""
    try:
        st = os.statvfs(path)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} TB"  # pragma: no cover


@dataclass(frozen=True)
class KeepSessions:
    """``KeepSessions = n``: at most ``n`` sessions (the current one included)."""

    count: int
    name: str = "keep_sessions"

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        """The oldest candidates past the count, acknowledged ones first."""
        excess = len(view.sessions) - self.count
        why = f"KeepSessions = {self.count}: {len(view.sessions)} sessions"
        return [(s, why) for s in view.candidates[: max(excess, 0)]]


@dataclass(frozen=True)
class MaxLogSize:
    """``MaxLogSize = bytes``: the sessions together hold at most this much."""

    size: int
    name: str = "max_log_size"

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        """Candidates in order until what is left fits."""
        held = view.size
        chosen = []
        for session in view.candidates:
            if held <= self.size:
                break
            chosen.append((session, f"MaxLogSize = {_size(self.size)}: {_size(held)} held"))
            held -= session.size
        return chosen


@dataclass(frozen=True)
class FreeSpace:
    """The guard's: acknowledged sessions, oldest first, until ``free`` bytes are free.

    Only acknowledged ones: the shore holds them. An unacknowledged session is removed only
    by a bound the operator set (``KeepSessions``, ``MaxLogSize``); a disk that fills with
    sessions nobody has collected stops the recording, loudly, rather than lose them.
    """

    free: int
    name: str = "min_free_disk"

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        """Acknowledged candidates until the free space would reach ``free``."""
        if view.free is None:
            return []
        free = view.free
        chosen = []
        for session in view.candidates:
            if free >= self.free or not session.acknowledged:
                break
            chosen.append((session, f"MinFreeDisk: {_size(free)} free"))
            free += session.size
        return chosen


@dataclass
class DiskGuard:
    """The guard's and retention's state (one object on the Recorder)."""

    settings: DiskSettings
    #: when the free space is checked next, when it was last, and what it was
    check_at: float = 0.0
    checked_at: float = 0.0
    free: int | None = None
    #: writing stopped by the guard (the reason shown), and how often it stopped
    stopped: str | None = None
    stops: int = 0
    #: retention: when it runs next; a pass is running; one more was asked meanwhile
    retain_at: float = 0.0
    soon_at: float = 0.0
    running: bool = False
    again: bool = False
    #: what retention did: sessions removed, bytes freed, the last pass's problems
    removed: int = 0
    freed: int = 0
    problems: list[str] = field(default_factory=list)
    last: list[str] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    thread: threading.Thread | None = None

    @property
    def resume(self) -> int:
        """The free space writing resumes at."""
        low = self.settings.min_free
        return max(low + max(int(low * MARGIN), 1 << 20), MIN_FREE_BYTES) if low else 0

    def policies(self) -> list[Any]:
        """The retention policies the settings ask for (the guard's always)."""
        settings = self.settings
        chosen: list[Any] = []
        if settings.min_free:
            chosen.append(FreeSpace(self.resume))
        if settings.keep_sessions is not None:
            chosen.append(KeepSessions(settings.keep_sessions))
        if settings.max_log_size is not None:
            chosen.append(MaxLogSize(settings.max_log_size))
        return chosen


class DiskKeeping(ModeKeeping):
    """The disk half of the Recorder: the free-space guard and retention (a mixin)."""

    _disk: DiskGuard
    commands: CommandHandler

    def _resume_free(self) -> int:
        """The free space writing needs to resume after a stop."""
        return max(self._disk.resume, MIN_FREE_BYTES)

    def _disk_refused(self) -> str | None:
        """Why no session may open now (the guard has stopped writing), or None."""
        return self._disk.stopped

    def _disk_tick(self, now: float) -> None:
        """Check the free space once a second; stop writing below MinFreeDisk; retain.

        Without MinFreeDisk nothing depends on the free space: it is read when the status
        asks for it (:meth:`disk_status`), not every second.
        """
        guard = self._disk
        if guard.settings.min_free and now >= guard.check_at:
            self._guard_check(now)
        if guard.settings.retention and now >= guard.retain_at:
            self.retain(now)

    def _guard_check(self, now: float) -> None:
        guard = self._disk
        guard.checked_at = now
        free = guard.free = free_bytes(self.log_root)
        low = guard.settings.min_free
        near = free is not None and low and free < 2 * guard.resume
        guard.check_at = now if near else now + CHECK_INTERVAL
        if free is not None and low and free < guard.resume and now >= guard.soon_at:
            guard.soon_at = now + CHECK_INTERVAL  # a pass a second at most while low
            self.retain(now, soon=True)  # acknowledged sessions make room, if any
        if free is not None and low and free < low:
            if guard.stopped is None:
                self._disk_stop(now, free)
        elif guard.stopped is not None and free is not None and free >= guard.resume:
            guard.stopped = None

    def _disk_due(self) -> float:
        """Return when :meth:`_disk_tick` next has work (epoch; inf: nothing timed).

        The guard's check once a second (at every tick as well once near the bound), and
        retention's next pass.
        """
        guard = self._disk
        due = math.inf
        if guard.settings.min_free:
            due = guard.checked_at + CHECK_INTERVAL
        if guard.settings.retention and guard.policies():
            due = min(due, guard.retain_at)
        return due

    def _disk_stop(self, now: float, free: int) -> None:
        guard = self._disk
        low = guard.settings.min_free
        guard.stopped = (
            f"{self.log_root} has {_size(free)} free, below MinFreeDisk {_size(low)}: "
            f"writing stops until {_size(guard.resume)} are free"
        )
        guard.stops += 1
        self.debug(f"disk guard: {guard.stopped}")
        self._stop_writing(now)

    def _stop_writing(self, now: float) -> None:
        """Close the session; what arrives is lost (reason ``low-disk``) until space returns."""
        if self.session is not None:
            self._close_session()
        self._set_broken(LOW_DISK, now)

    def _open_session(self, path: str | None = None) -> SessionWriter:
        session = super()._open_session(path)
        self._disk.retain_at = 0.0  # a new session: bounds are checked at the next tick
        return session

    # -- retention

    def retain(self, now: float, *, soon: bool = False) -> None:
        """Run a retention pass in its own thread (one at a time, and one more after it).

        Args:
            now: the recorder's clock.
            soon: the guard asks (free space is low): run even if a pass ran lately.
        """
        guard = self._disk
        if not guard.policies():
            return
        if not soon and now < guard.retain_at:
            return
        guard.retain_at = now + RETENTION_INTERVAL
        with guard.lock:
            if guard.running:
                guard.again = True
                return
            guard.running = True
        thread = threading.Thread(target=self._retain_loop, name="fleetlog-retention", daemon=True)
        guard.thread = thread
        thread.start()

    def retention_idle(self, timeout: float = 30.0) -> bool:
        """Wait for the retention pass in progress, if any; True when none runs."""
        thread = self._disk.thread
        if thread is not None:
            thread.join(timeout)
            return not thread.is_alive()
        return True

    def _retain_loop(self) -> None:
        guard = self._disk
        while True:
            self._retain_once()
            with guard.lock:
                if not guard.again:
                    guard.running = False
                    return
                guard.again = False

    def _retain_once(self) -> None:
        """One pass: survey, plan, delete (retention's thread)."""
        guard = self._disk
        pruner = self.commands.pruner  # the log server's digests and fetches, as prune uses
        try:
            result = retention.run(
                self.log_root,
                guard.policies(),
                current=self.current_session_name,
                fetching=pruner.fetching,
                digest=pruner.digest,
            )
        except StorageError as err:
            guard.problems = [str(err)]
            self.debug(f"retention failed: {err}")
            return
        except Exception as err:  # a thread of its own: never die without a word
            guard.problems = [f"retention failed: {err}"]
            self.debug(f"retention failed: {err}")
            return
        guard.removed += len(result.removed)
        guard.freed += result.freed
        guard.last = [r.session.name for r in result.removed]
        guard.problems = [f"{name}: {why}" for name, why in result.failed.items()]
        for removal in result.removed:
            self.debug(
                f"retention removed session {removal.session.name} "
                f"({_size(removal.session.size)}; {removal.policy}: {removal.why})"
            )
        for problem in guard.problems:
            self.debug(f"retention could not remove {problem}")

    def disk_status(self) -> dict[str, Any]:
        """The guard's and retention's state for the status reply."""
        guard = self._disk
        settings = guard.settings
        return {
            "free": guard.free if settings.min_free else free_bytes(self.log_root),
            "min_free": settings.min_free,
            "resume_at": guard.resume,
            "stopped": guard.stopped,
            "stops": guard.stops,
            "keep_sessions": settings.keep_sessions,
            "max_log_size": settings.max_log_size,
            "removed": guard.removed,
            "freed": guard.freed,
            "last_removed": list(guard.last),
            "problems": list(guard.problems),
        }
