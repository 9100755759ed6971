"""Session metadata on disk: the atomic file, the live recorder's lock, cut sessions, acks.

* ``<session>/.fleetlog-session.json`` is replaced atomically: written to a hidden temporary
  file, fsynced, renamed over the old one, and the directory fsynced.
* **Who is alive.** The recorder writing a session holds an exclusive ``flock`` on the session
  *directory* (no extra file in it) for as long as the session is open, and until its
  closing metadata is on disk. The kernel drops the lock when the process dies, however it
  dies (SIGKILL, OOM, a panic in a library), and it cannot be fooled by a reused pid or a
  recorder whose Zenoh session is merely disconnected: a session whose file says ``open``
  and whose directory nobody has locked has no live recorder, so it is *cut*. Where
  ``flock`` is not supported (some network file systems), the file's host, pid and boot id
  decide instead.
* **A cut session's last sign of life** is the later of its file's ``updated`` and the last
  ``PLOGGER_STATUS`` line in its plain alog's tail (the recorder logs its own status every
  2 s, and rewrites the file only every :data:`IDLE_REWRITE` s while that is all it logs).
* ``<logroot>/.fleetlog-acks.jsonl``: the shore collector's acknowledgements, appended one
  JSON line at a time after checking that the session and its files exist.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import json
import os
import socket
import stat
import time
from collections.abc import Mapping
from pathlib import Path

from fleetlog.errors import FormatError, StorageError
from fleetlog.storage.alogtail import read_tail
from fleetlog.storage.columns import polars_module
from fleetlog.wire.session_meta import ACKS_NAME, CUT, MAX_META_BYTES, META_NAME, OPEN, SessionMeta

__all__ = [
    "DirLock",
    "append_ack",
    "boot_id",
    "host_name",
    "last_status",
    "mark_cut_sessions",
    "read_meta",
    "recorder_alive",
    "session_state",
    "write_meta",
]

_TMP_SUFFIX = ".tmp"
#: An open session's metadata is rewritten at least this often (seconds) while counters
#: change; more often (2 s) while more than its recorder's own status lines are logged.
IDLE_REWRITE = 10.0
#: The bytes of a cut session's alog looked at for its recorder's last status line: the
#: tail of an idle log holds several; a busy one's file was rewritten within 2 s anyway.
_STATUS_TAIL = 64 << 10
#: The recorder's own status variable (pLogger's), logged every 2 s.
_STATUS_VAR = "PLOGGER_STATUS"
_BOOT_ID = Path("/proc/sys/kernel/random/boot_id")
#: attempts to take a session's lock that a short probe (a listing) may hold for microseconds
_LOCK_TRIES = 5


def boot_id() -> str:
    """Return the host's boot id (empty if the system has none)."""
    try:
        return _BOOT_ID.read_text().strip()
    except OSError:
        return ""


def host_name() -> str:
    """Return the host's name."""
    return socket.gethostname()


def _open_dir(path: Path) -> int:
    return os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)


class DirLock:
    """An exclusive ``flock`` on a session directory, held while its recorder is alive.

    Args:
        path: the session directory.

    Raises:
        StorageError: another live process holds it, or the directory cannot be opened.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.fd: int | None = _open_dir(path)
        except OSError as err:
            msg = f"cannot open the session directory {path}: {err.strerror}"
            raise StorageError(msg) from err
        #: False where the file system does not support flock (the directory is still used)
        self.held = False
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self.fd)
            self.fd = None
            msg = f"{path} is being written by another live recorder"
            raise StorageError(msg) from None
        except OSError:
            pass  # no flock here: liveness falls back to host, pid and boot id
        else:
            self.held = True

    def release(self) -> None:
        """Drop the lock (closing the descriptor releases it)."""
        fd, self.fd = self.fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


def write_meta(directory: Path, meta: SessionMeta | bytes, *, durable: bool = True) -> None:
    """Replace ``directory/.fleetlog-session.json`` atomically (and durably).

    Args:
        directory: the session directory.
        meta: the metadata (or its bytes).
        durable: fsync the file before the rename and the directory after it; without, the
            replacement survives the process (not a power cut) and costs no disk wait.

    Raises:
        StorageError: the file or the rename could not be written (names the file and why).
    """
    data = meta if isinstance(meta, bytes) else meta.to_bytes()
    final = directory / META_NAME
    tmp = directory / (META_NAME + _TMP_SUFFIX)
    try:
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC | os.O_NOFOLLOW
        fd = os.open(tmp, flags, 0o644)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            if durable:
                os.fsync(fd)
        finally:
            os.close(fd)
        os.rename(tmp, final)
        if durable:
            dfd = _open_dir(directory)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
    except OSError as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        msg = f"cannot write {final}: {err.strerror or err}"
        raise StorageError(msg) from err


def read_meta(directory: Path) -> SessionMeta | None:
    """Read a session's metadata; None if it has none.

    Raises:
        StorageError: the file exists but cannot be read.
        FormatError: it is not a metadata file this fleetlog reads.
    """
    path = directory / META_NAME
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except FileNotFoundError:
        return None
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror}"
        raise StorageError(msg) from err
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            msg = f"{path} is not a regular file"
            raise StorageError(msg)
        chunks: list[bytes] = []
        size = 0
        while size <= MAX_META_BYTES:
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror}"
        raise StorageError(msg) from err
    finally:
        os.close(fd)
    try:
        return SessionMeta.from_bytes(b"".join(chunks))
    except FormatError as err:
        raise FormatError(err.reason, str(path)) from None


def _lock_state(directory: Path, how: int) -> tuple[bool | None, int | None]:
    """Try ``flock(how | LOCK_NB)`` on a directory.

    Returns:
        (True, fd) if taken, (False, None) if held elsewhere, (None, None) if the file
        system cannot tell.
    """
    try:
        fd = _open_dir(directory)
    except OSError:
        return None, None
    for attempt in range(_LOCK_TRIES):
        try:
            fcntl.flock(fd, how | fcntl.LOCK_NB)
        except BlockingIOError:
            if attempt + 1 < _LOCK_TRIES:
                time.sleep(0.002 * (attempt + 1))
            continue
        except OSError:
            os.close(fd)
            return None, None
        return True, fd
    os.close(fd)
    return False, None


def _alive_by_process(meta: SessionMeta) -> bool:
    """Liveness without a lock: same host and boot, and the pid still runs."""
    if not meta.host or meta.host != host_name() or not meta.pid:
        return True  # another host's recorder: nothing here can tell, so never cut it
    if meta.boot and meta.boot != boot_id():
        return False  # the host rebooted since
    try:
        os.kill(meta.pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _foreign(meta: SessionMeta | None) -> bool:
    """A session written on another host (fetched while open, say): only that host can tell."""
    return meta is not None and bool(meta.host) and meta.host != host_name()


def recorder_alive(directory: Path, meta: SessionMeta | None = None) -> bool:
    """Return True if a live recorder holds ``directory`` (an ``open`` session's directory).

    A session another host wrote counts as alive: its lock is not here to ask (a copy
    fetched while it was being written is not cut).

    Args:
        directory: the session directory.
        meta: its metadata, for the host and the fallback where ``flock`` is not supported.
    """
    if _foreign(meta):
        return True
    taken, fd = _lock_state(directory, fcntl.LOCK_SH)
    if fd is not None:
        os.close(fd)
    if taken is None:
        return meta is None or _alive_by_process(meta)
    return not taken


def session_state(directory: Path, meta: SessionMeta) -> str:
    """Return a session's state as a reader reports it: ``open`` with no live recorder is ``cut``.

    ``meta`` was read before the lock was tested; a recorder writes its session's last
    version before it lets the lock go, so the file is read again once the lock is free,
    or a session closed in between (a LOGGER_RESTART) would be called cut.
    """
    if meta.state != OPEN or recorder_alive(directory, meta):
        return meta.state
    try:
        now = read_meta(directory)
    except (StorageError, FormatError):
        now = None
    return now.state if now is not None and now.state != OPEN else CUT


def last_status(directory: Path, meta: SessionMeta, now: float) -> float | None:
    """When the dead recorder of an open session last logged its status, if later than ``updated``.

    Read from the last :data:`_STATUS_TAIL` bytes of the session's plain alog (compressed
    ones are not read from the end: their file is rewritten every 2 s). A time beyond
    ``updated`` + :data:`IDLE_REWRITE` (+2 s) or after ``now`` cannot be the recorder's own
    (it rewrote the file at least that often, and the line is in the past), so the answer
    stays within that window whatever the log holds. None when the tail says nothing later.
    """
    if meta.logstart is None or meta.updated is None:
        return None
    alog = directory / f"{directory.name}.alog"
    try:
        if not stat.S_ISREG(alog.lstat().st_mode):
            return None
        tail = read_tail(alog, _STATUS_TAIL)
    except (OSError, StorageError):
        return None
    pl = polars_module()
    latest = min(now, meta.updated + IDLE_REWRITE + 2.0)
    times = tail.filter(pl.col("var") == _STATUS_VAR)["offset"] + meta.logstart
    times = times.filter(times.is_finite() & (times > meta.updated) & (times <= latest))
    return float(times.max()) if times.len() else None  # type: ignore[arg-type]


def mark_cut_sessions(log_root: Path, now: float) -> list[SessionMeta]:
    """Mark ``cut`` every session under ``log_root`` left ``open`` by a recorder that died.

    Each is checked and marked under its directory's lock, so a recorder that is alive (or
    one that starts at the same moment) is never marked. Unreadable sessions, and sessions
    another host wrote (copies fetched while open), are left alone.

    Returns:
        The new metadata of the sessions marked, oldest name first.
    """
    marked: list[SessionMeta] = []
    try:
        with os.scandir(log_root) as it:
            dirs = sorted(e.name for e in it if e.is_dir(follow_symlinks=False))
    except OSError:
        return marked
    for name in dirs:
        directory = log_root / name
        try:
            meta = read_meta(directory)
        except (StorageError, FormatError):
            continue
        if meta is None or meta.state != OPEN or _foreign(meta):
            continue
        taken, fd = _lock_state(directory, fcntl.LOCK_EX)
        try:
            if taken is False or (taken is None and _alive_by_process(meta)):
                continue
            # Read again under the lock: the recorder may have closed it meanwhile.
            try:
                meta = read_meta(directory)
            except (StorageError, FormatError):
                continue
            if meta is None or meta.state != OPEN:
                continue
            cut = meta.with_state(CUT, now)
            last = last_status(directory, meta, now)
            if last is not None:
                cut = dataclasses.replace(cut, updated=last)
            try:
                write_meta(directory, cut)
            except StorageError:
                continue
            marked.append(cut)
        finally:
            if fd is not None:
                os.close(fd)
    return marked


def append_ack(
    log_root: Path, session: str, files: Mapping[str, str], *, now: float, source: str = ""
) -> None:
    """Record that the shore holds ``files`` (name → sha256) of ``session``.

    The session must be a directory directly under the log root (not a symlink) and every
    name one of its regular files. One JSON line is appended with a single write.

    Raises:
        StorageError: no such session or file, or the acknowledgement cannot be written.
    """
    directory = log_root / session
    try:
        st = os.lstat(directory)
    except OSError:
        st = None
    if st is None or not stat.S_ISDIR(st.st_mode):
        msg = f"no session {session!r} in this log root"
        raise StorageError(msg)
    for name in files:
        try:
            fst = os.lstat(directory / name)
        except OSError:
            fst = None
        if fst is None or not stat.S_ISREG(fst.st_mode):
            msg = f"session {session!r} has no file {name!r}"
            raise StorageError(msg)
    line = json.dumps(
        {"time": now, "session": session, "files": dict(files), "source": source},
        separators=(",", ":"),
    )
    path = log_root / ACKS_NAME
    try:
        fd = os.open(
            path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644
        )
        try:
            data = (line + "\n").encode()
            if os.write(fd, data) != len(data):
                raise OSError(errno.EIO, "short write")
        finally:
            os.close(fd)
    except OSError as err:
        msg = f"cannot append to {path}: {err.strerror or err}"
        raise StorageError(msg) from err
