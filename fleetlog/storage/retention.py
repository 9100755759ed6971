"""Retention: the one place that deletes sessions from a log root.

Whatever asks for room (the shore's acknowledged prune, and the recording modes'
``KeepSessions`` / ``MaxLogSize`` / free-disk guard), the deleting is done here, the same way
(``../shared/DESIGN_NOTES.md``, "Deleting sessions"):

* **never the current session** (the one the recorder writes), nor a session a live recorder
  holds (its directory's ``flock``, :mod:`fleetlog.storage.metafile`);
* **never a session being fetched**: the log server holds a shared lease on each file it is
  sending (:mod:`fleetlog.storage.leases`), and a session is deleted only under an exclusive
  lock of every file, taken just before; the caller may also name sessions it knows are being
  fetched (``fetching``);
* **acknowledged sessions before unacknowledged ones**: a session is *acknowledged* when
  every entry in its directory is a regular file that the shore acknowledged
  (``<logroot>/.fleetlog-acks.jsonl``) with the sha256 the file has *now*. An ack that names
  other bytes, a file added since, a subdirectory or a symlink make it unacknowledged.

The decision is separate from the deed, so a policy is an input and is tested without
deleting anything:

1. :func:`survey` looks at the log root once: every session, oldest first
   (:class:`StoredSession`: files, size, acknowledged, and why it is protected, if it is),
   and the disk's free space (:class:`RetentionView`);
2. :func:`plan` asks each :class:`Policy` which of :attr:`RetentionView.candidates` (the
   deletable sessions, acknowledged oldest first, then unacknowledged oldest first) to
   remove, and why;
3. :func:`apply` removes them in that order, each only after checking again, under its
   locks, that it is still not current, not held by a recorder and not being fetched.

:func:`run` does the three. A policy is any object with a ``name`` and a
``choose(view) -> Iterable[tuple[StoredSession, str]]`` method; :class:`PruneAcknowledged`
is the shore's (``prune`` control command). A size policy walks ``view.candidates`` in order
and stops when enough is freed (see :class:`RetentionView` for the figures it needs).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shutil
import stat
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.naming import parse_session_root
from fleetlog.storage.download import sha256_file
from fleetlog.storage.leases import exclusive_files
from fleetlog.storage.metafile import read_meta, recorder_alive
from fleetlog.storage.sessionalog import ALOG_SUFFIXES, holds_alog
from fleetlog.wire.query import check_component
from fleetlog.wire.session_meta import ACKS_NAME, OPEN

__all__ = [
    "ALOG_SUFFIXES",
    "CURRENT",
    "FETCHING",
    "LIVE",
    "Plan",
    "Policy",
    "PruneAcknowledged",
    "Removal",
    "RetentionResult",
    "RetentionView",
    "StoredSession",
    "apply",
    "plan",
    "read_acks",
    "run",
    "survey",
]

#: what makes a directory under the log root a session (as the catalog says)
#: why a session is protected
CURRENT = "it is the session being recorded"
LIVE = "a live recorder holds it"
FETCHING = "it is being fetched"
#: the acknowledgements file is read up to this size (a line per acknowledged session)
MAX_ACKS_BYTES = 64 << 20
_SHA256_LEN = 64


def read_acks(log_root: Path) -> dict[str, dict[str, set[str]]]:
    """Read ``<logroot>/.fleetlog-acks.jsonl``: session → file name → acknowledged sha256s.

    The file is appended by the recorder's ``ack`` command
    (:func:`fleetlog.storage.metafile.append_ack`). Lines that do not parse are skipped (a
    line cut by a power loss, say); a missing file is no acknowledgement at all.

    Raises:
        StorageError: the file exists but cannot be read.
    """
    path = log_root / ACKS_NAME
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        return {}
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror or err}"
        raise StorageError(msg) from err
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            msg = f"{path} is not a regular file"
            raise StorageError(msg)
        with os.fdopen(os.dup(fd), "rb") as file:
            data = file.read(MAX_ACKS_BYTES)
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror or err}"
        raise StorageError(msg) from err
    finally:
        os.close(fd)
    acks: dict[str, dict[str, set[str]]] = {}
    for line in data.splitlines():
        try:
            obj = json.loads(line)
        except (ValueError, RecursionError):
            continue
        if not isinstance(obj, dict):
            continue
        session, files = obj.get("session"), obj.get("files")
        if not isinstance(session, str) or not isinstance(files, dict):
            continue
        known = acks.setdefault(session, {})
        for name, digest in files.items():
            if isinstance(name, str) and isinstance(digest, str) and len(digest) == _SHA256_LEN:
                known.setdefault(name, set()).add(digest)
    return acks


@dataclass(frozen=True)
class StoredSession:
    """One session of the log root, as retention sees it.

    Attributes:
        name: its directory's name.
        path: its directory.
        files: its regular files' names and sizes.
        size: bytes in all (its regular files).
        order: the time stamp in its name (seconds), else its directory's mtime.
        acknowledged: the shore holds every file of it, verified (see the module docstring).
        protected: why it may not be deleted (:data:`CURRENT`, :data:`LIVE`,
            :data:`FETCHING`), or None.
    """

    name: str
    path: Path
    files: tuple[tuple[str, int], ...]
    size: int
    order: float
    acknowledged: bool = False
    protected: str | None = None


@dataclass(frozen=True)
class RetentionView:
    """A log root at one moment: what retention may choose from.

    Attributes:
        log_root: the log root.
        sessions: every session, oldest first (protected ones included).
        free: bytes an unprivileged writer may still use on its file system (None if unknown).
        total: the file system's size in bytes (None if unknown).
    """

    log_root: Path
    sessions: tuple[StoredSession, ...]
    free: int | None = None
    total: int | None = None

    @property
    def candidates(self) -> list[StoredSession]:
        """The sessions that may be deleted, in the order retention prefers.

        Acknowledged sessions first, oldest first; then unacknowledged ones, oldest first.
        Protected sessions are never among them.
        """
        free = [s for s in self.sessions if s.protected is None]
        return [s for s in free if s.acknowledged] + [s for s in free if not s.acknowledged]

    @property
    def size(self) -> int:
        """Bytes held by every session (the protected ones too)."""
        return sum(s.size for s in self.sessions)


class Policy(Protocol):
    """Chooses sessions to remove from a :class:`RetentionView`.

    ``choose`` returns sessions taken from ``view.candidates`` (others are ignored), each with
    one sentence saying why; the order given is the order of removal.
    """

    @property
    def name(self) -> str:
        """A short name, reported with each removal (``prune``, ``keep_sessions``...)."""
        ...

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        """Return the sessions to remove and why."""
        ...


@dataclass(frozen=True)
class PruneAcknowledged:
    """Remove every acknowledged session (the shore's ``prune`` request)."""

    name: str = "prune"

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        """Every acknowledged candidate, oldest first."""
        return [(s, "the shore holds it, verified") for s in view.candidates if s.acknowledged]


@dataclass(frozen=True)
class Removal:
    """A session chosen for removal, by which policy and why."""

    session: StoredSession
    policy: str
    why: str


@dataclass
class Plan:
    """What :func:`plan` chose.

    Attributes:
        view: the log root it was chosen from.
        remove: the sessions to remove, in order.
        kept: the sessions not chosen and why (protected, or no policy chose them).
    """

    view: RetentionView
    remove: list[Removal] = field(default_factory=list)
    kept: dict[str, str] = field(default_factory=dict)


@dataclass
class RetentionResult:
    """What :func:`apply` did.

    Attributes:
        removed: the sessions removed, in order (with the policy and why).
        skipped: sessions chosen but left, and why (they became current or fetched since).
        failed: sessions whose removal failed, and the error (some of their files may be
            gone).
        kept: the plan's kept sessions and why.
        freed: bytes freed.
    """

    removed: list[Removal] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    failed: dict[str, str] = field(default_factory=dict)
    kept: dict[str, str] = field(default_factory=dict)
    freed: int = 0


def _is_session(entry: os.DirEntry[str]) -> bool:
    try:
        check_component(entry.name, "session")
        if entry.name.startswith(".") or not entry.is_dir(follow_symlinks=False):
            return False
        return holds_alog(entry.path)
    except (OSError, FormatError):
        return False


def _order(name: str, path: Path) -> float:
    parsed = parse_session_root(name)
    if parsed is not None:
        with contextlib.suppress(OverflowError, OSError, ValueError):
            return parsed[1].timestamp()
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def _contents(path: Path) -> tuple[list[tuple[str, int]], bool]:
    """Return a session's regular files with their sizes, and whether that is all it holds."""
    files: list[tuple[str, int]] = []
    only_files = True
    with os.scandir(path) as it:
        for entry in it:
            try:
                st = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode):
                files.append((entry.name, st.st_size))
            else:
                only_files = False
    files.sort()
    return files, only_files


def _acknowledged(
    path: Path,
    files: Sequence[tuple[str, int]],
    only_files: bool,
    acked: Mapping[str, set[str]] | None,
    digest: Callable[[Path], str],
) -> bool:
    if not acked or not only_files or not files:
        return False
    if any(name not in acked for name, _ in files):
        return False  # cheap: no file is hashed unless every one was acknowledged
    try:
        return all(digest(path / name) in acked[name] for name, _ in files)
    except (StorageError, OSError):
        return False


def _live(path: Path) -> bool:
    """A recorder writes the session: its metadata says open and its lock is held."""
    try:
        meta = read_meta(path)
    except (StorageError, FormatError):
        return False
    return meta is not None and meta.state == OPEN and recorder_alive(path, meta)


def survey(
    log_root: Path,
    *,
    current: str | None,
    fetching: Collection[str] = (),
    acks: Mapping[str, Mapping[str, set[str]]] | None = None,
    digest: Callable[[Path], str] = sha256_file,
    acknowledged: bool = True,
) -> RetentionView:
    """Look at a log root once.

    Args:
        log_root: the directory holding the sessions.
        current: the session being recorded (never deleted), if any.
        fetching: sessions known to be fetched now (never deleted); the file leases are
            checked again by :func:`apply` in any case.
        acks: the acknowledgements (:func:`read_acks` of the log root when None).
        digest: returns a file's sha256 (a cache of the log server's digests, or hashing).
        acknowledged: work out which sessions are acknowledged (hashing their files); a
            policy that does not care saves the reads.

    Raises:
        StorageError: the log root cannot be listed, or its acknowledgements read.
    """
    if acks is None and acknowledged:
        acks = read_acks(log_root)
    try:
        with os.scandir(log_root) as it:
            entries = [e for e in it if _is_session(e)]
    except OSError as err:
        msg = f"cannot list {log_root}: {err.strerror or err}"
        raise StorageError(msg) from err
    sessions: list[StoredSession] = []
    for entry in entries:
        path = Path(entry.path)
        try:
            files, only_files = _contents(path)
        except OSError:
            continue  # it vanished meanwhile
        protected: str | None = None
        if entry.name == current:
            protected = CURRENT
        elif entry.name in fetching:
            protected = FETCHING
        elif _live(path):
            protected = LIVE
        acked = (
            protected is None
            and acknowledged
            and acks is not None
            and _acknowledged(path, files, only_files, acks.get(entry.name), digest)
        )
        sessions.append(
            StoredSession(
                entry.name,
                path,
                tuple(files),
                sum(size for _, size in files),
                _order(entry.name, path),
                acked,
                protected,
            )
        )
    sessions.sort(key=lambda s: (s.order, s.name))
    free = total = None
    try:
        st = os.statvfs(log_root)
        free, total = st.f_bavail * st.f_frsize, st.f_blocks * st.f_frsize
    except OSError:
        pass
    return RetentionView(log_root, tuple(sessions), free, total)


def plan(view: RetentionView, policies: Iterable[Policy]) -> Plan:
    """Ask each policy what to remove; return the union, in the policies' order.

    A session chosen by two policies is removed once (the first one's reason is kept); a
    choice that is not a candidate (protected, or not of this view) is ignored.
    """
    candidates = {s.name: s for s in view.candidates}
    chosen: dict[str, Removal] = {}
    for policy in policies:
        for session, why in policy.choose(view):
            if session.name in candidates and session.name not in chosen:
                chosen[session.name] = Removal(candidates[session.name], policy.name, why)
    kept: dict[str, str] = {}
    for session in view.sessions:
        if session.name in chosen:
            continue
        if session.protected is not None:
            kept[session.name] = session.protected
        elif not session.acknowledged:
            kept[session.name] = "the shore has not acknowledged it"
        else:
            kept[session.name] = "no policy chose it"
    return Plan(view, list(chosen.values()), kept)


@contextlib.contextmanager
def _directory_lock(path: Path) -> Iterator[bool]:
    """Hold the session directory's lock exclusively; False if a live recorder holds it."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        yield True  # gone already, or not a directory any more: nothing to protect
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        except OSError:
            pass  # no flock on this file system: the metadata check stands
        yield True
    finally:
        os.close(fd)


def _remove(session: StoredSession) -> int:
    """Delete a session's directory; return the bytes freed.

    The alogs go last, so a removal cut short leaves a directory that is still a session
    (and still acknowledged: the next run finishes it), not an anonymous remnant.
    """
    path = session.path
    freed = 0
    files, _ = _contents(path)
    files.sort(key=lambda item: (item[0].endswith(ALOG_SUFFIXES), item[0]))
    for name, size in files:
        try:
            os.unlink(path / name)
        except FileNotFoundError:
            continue
        freed += size
    # What is not a regular file (only a session retention was told to remove whatever it
    # holds has any): removed without following symlinks.
    shutil.rmtree(path)
    return freed


def apply(
    chosen: Plan,
    *,
    current: Callable[[], str | None] = lambda: None,
    fetching: Callable[[], Collection[str]] = tuple,
) -> RetentionResult:
    """Remove the plan's sessions, in order, each checked again just before.

    A session is left (``skipped``) when it became the current one, is named by
    ``fetching()``, is held by a live recorder (its directory lock), or has a file under a
    fetch's lease (:mod:`fleetlog.storage.leases`). The directory lock and every file's
    exclusive lock are held while it is deleted, so no fetch starts on it meanwhile.

    Args:
        chosen: the plan.
        current: returns the session being recorded now.
        fetching: returns the sessions known to be fetched now.
    """
    result = RetentionResult(kept=dict(chosen.kept))
    for removal in chosen.remove:
        session = removal.session
        name = session.name
        if name == current() or name in fetching():
            result.skipped[name] = CURRENT if name == current() else FETCHING
            continue
        with _directory_lock(session.path) as unlocked:
            if not unlocked:
                result.skipped[name] = LIVE
                continue
            paths = [session.path / f for f, _ in session.files]
            with exclusive_files(paths) as free:
                if not free:
                    result.skipped[name] = FETCHING
                    continue
                try:
                    result.freed += _remove(session)
                except OSError as err:
                    if err.errno == errno.ENOENT:
                        result.removed.append(removal)
                        continue
                    result.failed[name] = f"cannot remove {name}: {err.strerror or err}"
                    continue
        result.removed.append(removal)
    return result


def run(
    log_root: Path,
    policies: Iterable[Policy],
    *,
    current: Callable[[], str | None] = lambda: None,
    fetching: Callable[[], Collection[str]] = tuple,
    digest: Callable[[Path], str] = sha256_file,
) -> RetentionResult:
    """Survey the log root, plan with ``policies``, and apply the plan.

    Raises:
        StorageError: the log root cannot be listed, or its acknowledgements read.
    """
    view = survey(log_root, current=current(), fetching=fetching(), digest=digest)
    return apply(plan(view, policies), current=current, fetching=fetching)
