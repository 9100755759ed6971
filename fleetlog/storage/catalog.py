"""The sessions of a log root, as the query services describe and serve them.

A *session* is a directory directly under the log root that holds an alog (``.alog``,
``.alog.gz`` or ``.alog.zst``): what fleetlog's recorder and real pLogger both write
(MOOS_FORMAT.md §1). Sessions are ordered by the time stamp in their name
(:func:`fleetlog.moos.naming.parse_session_root`), else by their directory's modification
time.

* **latest** — the session the recorder is writing, if it said so; else the one the
  ``.LastOpenedMOOSLogDirectory`` hint names (``--hint FILE``, else the hint in the log root,
  else in its parent, where pLogger leaves it: its working directory, usually the mission
  directory above ``Path``); else the newest. The hint is matched by the directory's last
  component, because pLogger writes the path as it was configured (absolute, or relative to
  its working directory), which rarely resolves the same way where the server runs.
* **complete** — a session is being written if it is the recorder's open session; without a
  recorder (``fleetlog serve`` of old or foreign directories), if its metadata says ``open``
  and a live recorder holds it, or, for a session without metadata (real pLogger's), if one
  of its files changed in the last few seconds.
* **state** — the session metadata's ``open``/``closed``/``cut``; an ``open`` session whose
  recorder is no longer alive is listed as ``cut`` (the next recorder start marks it so).
* Details read from the alog (LOGSTART, duration, vehicle, variables count) are cached by the
  alog's size and modification time, so listing again costs a ``stat`` per file.

Every path is confined to the log root (:mod:`fleetlog.storage.confined`). Files of a fetch
in progress (``*.part``, ``*.part.json``) are not listed: a shore directory that is served in
turn never offers half a file.
"""

from __future__ import annotations

import functools
import os
import re
import stat
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import TypeVar

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.naming import HINT_FILE_NAME, parse_hint_file, parse_session_root
from fleetlog.storage.alogscan import HeadInfo, VariableScan, is_compressed, read_head, tail_offset
from fleetlog.storage.confined import ConfinedRoot, DigestCache
from fleetlog.storage.leases import FileLeases
from fleetlog.storage.metafile import read_meta, recorder_alive, session_state
from fleetlog.storage.sessionalog import ALOG_SUFFIXES, holds_alog
from fleetlog.wire.query import FileInfo, FileMeta, LatestInfo, SessionInfo, check_component
from fleetlog.wire.session_meta import META_NAME, OPEN, SessionMeta

__all__ = ["ALOG_SUFFIXES", "QUIET_SECONDS", "LogCatalog", "disk_space"]

#: a session none of whose files changed for this long is complete (without a recorder)
QUIET_SECONDS = 5.0
_HINT_MAX = 4096
#: a fetch in progress (fleetlog.storage.download): never listed, never served as a log
_DOWNLOAD_SUFFIXES = (".part", ".part.json", ".part.json.tmp")
#: the metadata file while it is being replaced (never listed)
_META_TMP = META_NAME + ".tmp"
_COMMUNITY_LINE = re.compile(r"^[ \t]*community[ \t]*=(.*)$", re.IGNORECASE | re.MULTILINE)
_MOOS_HEAD = 64 << 10
#: alogs whose details are kept (a few hundred bytes each), and alogs still being written
#: whose scans are kept (their sets of variable names) to go on from where they stopped
_MAX_DETAILS = 1024
_MAX_SCANS = 4
_BUSY_LOCKS = 16
_T = TypeVar("_T")


@dataclass
class _Details:
    """What was read from a session's alog, and the alog state it belongs to."""

    identity: tuple[int, int, int]
    head: HeadInfo
    duration: float | None
    variables: int | None
    community: str | None


def _nothing() -> None:
    """Nothing to do after sending a range."""


def _alog_of(session: str, names: list[str]) -> str | None:
    """Pick the session's alog: the one named after the directory, else the first one."""
    for suffix in ALOG_SUFFIXES:
        if session + suffix in names:
            return session + suffix
    alogs = sorted(n for n in names if n.endswith(ALOG_SUFFIXES))
    return alogs[0] if alogs else None


class LogCatalog:
    """The sessions under a log root, their files and their details.

    Safe to use from several threads: details are computed under a lock per alog.

    Args:
        log_root: the directory holding the session directories.
        vehicle: the serving vehicle, used when a session does not say which one wrote it.
        active: returns the session directory the recorder is writing now (or None); given
            by the recorder, it decides which session is being written.
        hint: a ``.LastOpenedMOOSLogDirectory`` file to read instead of the default places.
        quiet: seconds without change after which a session counts as complete (without
            ``active``).
        clock: the wall clock (tests pass their own).

    Raises:
        StorageError: the log root is not a directory.
    """

    def __init__(
        self,
        log_root: str | os.PathLike[str],
        *,
        vehicle: str,
        active: Callable[[], str | os.PathLike[str] | None] | None = None,
        hint: str | os.PathLike[str] | None = None,
        quiet: float = QUIET_SECONDS,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.root = ConfinedRoot(log_root)
        self.vehicle = vehicle
        self.digests = DigestCache()
        #: the files being fetched now: retention deletes none of them (storage/leases.py)
        self.leases = FileLeases()
        self._active = active
        self._hint = Path(hint) if hint is not None else None
        self._quiet = quiet
        self._clock = clock
        self._lock = threading.Lock()
        # Bounded: a recorder restarted every minute for months lists many thousands of
        # sessions; what is kept per alog must not grow with them.
        self._details: OrderedDict[Path, _Details] = OrderedDict()
        self._scans: OrderedDict[Path, VariableScan] = OrderedDict()
        self._busy = tuple(threading.Lock() for _ in range(_BUSY_LOCKS))

    # -- listing

    def _entries(self, directory: Path) -> list[os.DirEntry[str]]:
        try:
            with os.scandir(directory) as it:
                return list(it)
        except OSError as err:
            msg = f"cannot list {directory}: {err.strerror or err}"
            raise StorageError(msg) from err

    def _session_files(self, session: str) -> list[tuple[str, os.stat_result]]:
        """Return the regular files of a session (confined), with their stat."""
        directory = self.root.resolve(session)
        files: list[tuple[str, os.stat_result]] = []
        for entry in self._entries(directory):
            try:
                check_component(entry.name, "file")
            except FormatError:
                continue
            if entry.name.endswith(_DOWNLOAD_SUFFIXES) or entry.name == _META_TMP:
                continue
            if entry.is_symlink() and not self.root.contains(entry.path):
                continue  # a symlink leaving the root is never listed (nor served)
            try:
                st = os.stat(entry.path)
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode):
                files.append((entry.name, st))
        files.sort()
        return files

    def _is_session_dir(self, entry: os.DirEntry[str]) -> bool:
        try:
            check_component(entry.name, "session")
            if not entry.is_dir() or not self.root.contains(entry.path):
                return False
            return holds_alog(entry.path)
        except (OSError, FormatError):
            return False

    def session_names(self) -> list[str]:
        """Return the sessions' names, oldest first.

        Raises:
            StorageError: the log root cannot be listed.
        """
        found: list[tuple[float, str]] = []
        for entry in self._entries(self.root.path):
            if self._is_session_dir(entry):
                found.append((self._order(entry.name, entry), entry.name))
        found.sort()
        return [name for _, name in found]

    @staticmethod
    def _order(name: str, entry: os.DirEntry[str] | None = None) -> float:
        parsed = parse_session_root(name)
        if parsed is not None:
            try:
                return parsed[1].timestamp()
            except (OverflowError, OSError, ValueError):
                pass  # a year the platform's mktime cannot take: order by mtime
        try:
            return entry.stat().st_mtime if entry is not None else 0.0
        except OSError:
            return 0.0

    def has_session(self, session: str) -> bool:
        """Return True if ``session`` names a session directory under the root."""
        try:
            return holds_alog(self.root.resolve(session))
        except (OSError, FormatError, StorageError):
            return False

    def _require(self, session: str) -> None:
        if not self.has_session(session):
            msg = f"no session {session!r} in this log root"
            raise StorageError(msg)

    # -- state

    def _active_path(self) -> Path | None:
        if self._active is None:
            return None
        try:
            current = self._active()
        except Exception:  # the recorder's view must never break a listing
            return None
        return None if current is None else Path(os.path.realpath(current))

    def active_session(self) -> str | None:
        """Return the name of the session the recorder is writing, if it is under the root."""
        current = self._active_path()
        if current is None or current.parent != self.root.path:
            return None
        return current.name

    def is_complete(
        self, session: str, files: list[tuple[str, os.stat_result]] | None = None
    ) -> bool:
        """Return True if ``session`` is no longer being written.

        Raises:
            StorageError: the session cannot be listed.
        """
        if self._active is not None:
            return session != self.active_session()
        meta = self._meta(session)
        if meta is not None:
            return meta.state != OPEN or not recorder_alive(self.root.resolve(session), meta)
        if files is None:
            files = self._session_files(session)
        newest = max((st.st_mtime for _, st in files), default=0.0)
        return newest < self._clock() - self._quiet

    def _meta(self, session: str) -> SessionMeta | None:
        """Read a session's metadata; None without one, or one that cannot be read."""
        try:
            return read_meta(self.root.resolve(session))
        except (StorageError, FormatError):
            return None

    def state(self, session: str, meta: SessionMeta | None = None) -> str | None:
        """Return the session's state: ``open``, ``closed``, ``cut``, or None without metadata.

        An ``open`` session is ``cut`` when no live recorder holds it.
        """
        if meta is None:
            meta = self._meta(session)
        if meta is None:
            return None
        if meta.state != OPEN or session == self.active_session():
            return meta.state
        return session_state(self.root.resolve(session), meta)

    # -- sessions

    def session(self, session: str, *, brief: bool = False) -> SessionInfo:
        """Describe one session.

        Args:
            session: its name.
            brief: names, files, sizes and completeness only, without reading the alog.

        Raises:
            FormatError: the name is not a single path component.
            StorageError: no such session, or it cannot be read.
        """
        self._require(session)
        files = self._session_files(session)
        parsed = parse_session_root(session)
        meta = self._meta(session)
        synced = meta.clock.get("synchronized") if meta is not None else None
        info = SessionInfo(
            name=session,
            files=tuple(FileInfo(name, st.st_size, st.st_mtime) for name, st in files),
            complete=self.is_complete(session, files),
            stamp=parsed[1].replace(microsecond=0).isoformat() if parsed else None,
            alog=_alog_of(session, [name for name, _ in files]),
            state=self.state(session, meta),
            synced=synced if isinstance(synced, bool) else None,
            mission_id=meta.mission_id if meta is not None else None,
            part=meta.part if meta is not None else None,
            notes=dict(meta.notes) if meta is not None else {},
            tags=tuple(meta.tags) if meta is not None else (),
            opened=meta.opened if meta is not None else None,
        )
        if brief or info.alog is None:
            return info
        details = self._details_of(session, info.alog, dict(files)[info.alog])
        head = details.head
        return SessionInfo(
            name=info.name,
            files=info.files,
            complete=info.complete,
            stamp=info.stamp,
            alog=info.alog,
            start=head.banner.logstart if head.banner else None,
            duration=details.duration,
            vehicle=details.community or self.vehicle,
            variables=details.variables,
            state=info.state,
            synced=info.synced,
            mission_id=info.mission_id,
            part=info.part,
            notes=info.notes,
            tags=info.tags,
            opened=info.opened,
        )

    def sessions(self, *, brief: bool = False) -> list[SessionInfo]:
        """Describe every session, oldest first; sessions that vanish meanwhile are left out.

        A session whose alog cannot be read (corrupt compression) is listed as ``brief``
        lists it: left out, it would vanish from the listing while ``latest`` names it.

        Raises:
            StorageError: the log root cannot be listed.
        """
        out: list[SessionInfo] = []
        for name in self.session_names():
            try:
                out.append(self.session(name, brief=brief))
            except StorageError:
                try:
                    out.append(self.session(name, brief=True))
                except StorageError:
                    continue  # it vanished meanwhile
        return out

    def _details_of(self, session: str, alog: str, st: os.stat_result) -> _Details:
        path = self.root.resolve(session, alog)
        identity = (st.st_ino, st.st_size, st.st_mtime_ns)
        with self._lock:
            known = self._details.get(path)
        if known is not None and known.identity == identity:
            return known
        # one scan at a time per alog (a striped lock: a lock per path would be kept forever)
        with self._busy[hash(path) % _BUSY_LOCKS]:
            with self._lock:
                known = self._details.get(path)
                scan = self._scans.pop(path, None)
            if known is not None and known.identity == identity:
                if scan is not None:
                    self._keep(self._scans, path, scan, _MAX_SCANS)
                return known
            head = read_head(path)
            scan = scan or VariableScan(path)
            scan.update()
            duration = scan.last_offset if is_compressed(path) else tail_offset(path)
            community = head.community or self._moos_community(session)
            details = _Details(identity, head, duration, scan.count, community)
            # Only an alog that may still grow needs its scan (to go on from where it
            # stopped); a complete one's details say all, and its set of names is let go.
            growing = not is_compressed(path) and not self.is_complete(session)
            with self._lock:
                if growing:
                    self._keep(self._scans, path, scan, _MAX_SCANS)
                self._keep(self._details, path, details, _MAX_DETAILS)
            return details

    def cached(self) -> dict[str, int]:
        """Return how much the catalog keeps: ``details`` and ``scans`` (alogs), ``names``."""
        with self._lock:
            names = sum(scan.count for scan in self._scans.values())
            return {"details": len(self._details), "scans": len(self._scans), "names": names}

    @staticmethod
    def _keep(cache: OrderedDict[Path, _T], path: Path, value: _T, limit: int) -> None:
        # Under the lock: the newest last; the oldest go beyond ``limit``.
        cache[path] = value
        cache.move_to_end(path)
        while len(cache) > limit:
            cache.popitem(last=False)

    def head(self, session: str) -> tuple[str, HeadInfo]:
        """Return a session's alog name and what its head says (for the remote grep).

        Raises:
            StorageError: no such session, or it holds no alog.
        """
        info = self.session(session, brief=True)
        if info.alog is None:
            msg = f"session {session!r} holds no alog"
            raise StorageError(msg)
        return info.alog, read_head(self.root.resolve(session, info.alog))

    def alog_path(self, session: str) -> Path:
        """Return the confined real path of a session's alog.

        Raises:
            StorageError: no such session, or it holds no alog.
        """
        alog, _ = self.head(session)
        return self.root.resolve(session, alog)

    def _moos_community(self, session: str) -> str | None:
        for name, _ in self._session_files(session):
            if not name.endswith("._moos"):
                continue
            try:
                with self.root.open(session, name) as (fd, _st):
                    text = os.pread(fd, _MOOS_HEAD, 0).decode("utf-8", "replace")
            except (OSError, StorageError, FormatError):
                continue
            match = _COMMUNITY_LINE.search(text)
            if match:
                value = "".join(match.group(1).split())
                if value:
                    return value
        return None

    # -- latest

    def _hint_files(self) -> list[Path]:
        if self._hint is not None:
            return [self._hint]
        return [self.root.path / HINT_FILE_NAME, self.root.path.parent / HINT_FILE_NAME]

    def read_hint(self) -> str | None:
        """Return the directory the first readable hint file names, as written."""
        for path in self._hint_files():
            try:
                with path.open("rb") as file:
                    text = file.read(_HINT_MAX).decode("utf-8", "surrogateescape")
                return parse_hint_file(text, str(path))
            except (OSError, FormatError):
                continue
        return None

    def latest(self) -> LatestInfo:
        """Find the latest session (see the module docstring).

        Raises:
            StorageError: the log root cannot be listed.
        """
        hint = self.read_hint()
        active = self.active_session()
        name: str | None = None
        how = "newest"
        if active is not None and self.has_session(active):
            name, how = active, "recorder"
        elif hint is not None:
            candidate = PurePosixPath(hint.rstrip("/")).name
            if candidate and self.has_session(candidate):
                name, how = candidate, "hint"
        if name is None:
            names = self.session_names()
            name = names[-1] if names else None
        if name is None:
            return LatestInfo(self.vehicle, None, False, how, hint)
        start = None
        try:
            _, head = self.head(name)
            start = head.banner.logstart if head.banner else None
        except StorageError:
            pass
        meta = self._meta(name)
        synced = meta.clock.get("synchronized") if meta is not None else None
        return LatestInfo(
            self.vehicle,
            name,
            not self.is_complete(name),
            how,
            hint,
            start,
            synced=synced if isinstance(synced, bool) else None,
        )

    def guess_vehicle(self) -> str | None:
        """Return the community that wrote the latest session, if it says (for ``serve``).

        Reads the alog's head and the ``._moos`` only, never the whole alog.
        """
        latest = self.latest().session
        if latest is None:
            return None
        try:
            _, head = self.head(latest)
        except StorageError:
            return self._moos_community(latest)
        return head.community or self._moos_community(latest)

    # -- files

    def read_range(
        self, session: str, name: str, offset: int, length: int
    ) -> tuple[bytes, FileMeta]:
        """Read a byte range of a session's file.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: no such session or file, a path leaving the root, or an offset past
                the end of the file.
        """
        data, meta, _ = self.serve_range(session, name, offset, length)
        return data, meta

    def serve_range(
        self, session: str, name: str, offset: int, length: int
    ) -> tuple[bytes, FileMeta, Callable[[], None]]:
        """Read a byte range as :meth:`read_range`, and return what to do once it is sent.

        The third value hashes the bytes into the file's digest (:meth:`DigestCache.feed`)
        when the session is complete and the file stayed the same during the read; call it
        after the reply is sent, so the hashing never delays the bytes.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`read_range`.
        """
        self._require(session)
        data, st, steady = self.root.read_steady((session, name), offset, length)
        complete = self.is_complete(session)
        meta = FileMeta(offset, len(data), st.st_size, st.st_mtime, complete)
        if length:  # a question about the file (its digest) is no download
            finished = complete and offset + len(data) >= st.st_size
            self.leases.served(self.root.resolve(session, name), st, finished=finished)
        if not (complete and steady and data):
            return data, meta, _nothing
        return data, meta, functools.partial(self.digests.feed, st, offset, data)

    def warm_digests(
        self, session: str, cancel: threading.Event, pause: Callable[[float], None]
    ) -> None:
        """Compute the digests of a complete session's files before anyone asks for them.

        See :meth:`DigestCache.warm`; a session still being written is left alone.

        Raises:
            StorageError: the session cannot be listed.
        """
        if not self.has_session(session):
            return
        for name, _ in self._session_files(session):
            if cancel.is_set() or not self.is_complete(session):
                return
            self.digests.warm(self.root, (session, name), cancel, pause)

    def file_digest(
        self, session: str, name: str, cancel: threading.Event | None = None
    ) -> FileMeta:
        """Return a file's meta with the sha256 of the whole file, if the session is complete.

        A file of a session still being written has no final digest: ``sha256`` is None.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`read_range`, or the file changed while being hashed.
        """
        self._require(session)
        if not self.is_complete(session):
            _, st = self.root.read_range((session, name), 0, 0)
            return FileMeta(0, 0, st.st_size, st.st_mtime, False)
        digest, st = self.digests.sha256(self.root, (session, name), cancel)
        # A fetch asks for the digest once the bytes are here: its lease ends (one that
        # goes on, a resumed fetch, takes a new lease with its next range).
        self.leases.served(self.root.resolve(session, name), st, finished=True)
        return FileMeta(0, 0, st.st_size, st.st_mtime, True, digest)


def disk_space(path: Path) -> dict[str, int] | None:
    """Return ``{"free", "total"}`` bytes of the file system holding ``path`` (None if unknown).

    ``free`` is what an unprivileged writer may still use (``f_bavail``), as the recorder
    would find it.
    """
    try:
        st = os.statvfs(path)
    except OSError:
        return None
    return {"free": st.f_bavail * st.f_frsize, "total": st.f_blocks * st.f_frsize}
