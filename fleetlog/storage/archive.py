"""The shore archive that ``fleetlog collect`` fills, and its records of what it holds.

Layout (the one ``fetch --all`` writes; pLogger's session and file names kept)::

    ARCHIVE/
      .fleetlog-collect.lock        held (flock) by the collector running on ARCHIVE
      VEHICLE/                      VEHICLE@ZID when two processes answer for one vehicle
        .fleetlog-archive.json      the collector's record of this vehicle (below)
        SESSION/FILE...             complete, verified files; FILE.part while in flight

The record says, per session, what is on shore (each verified file's size and sha256), what
the vehicle listed last, whether the session is ``complete`` (closed and all here),
``cut`` (its recorder died with it open; all it wrote is here), ``partial`` or ``missing``,
and whether the vehicle acknowledged and pruned it; per vehicle, when it was last seen and
what is in flight. It is replaced atomically (write, fsync, rename) and read back
defensively: a record that cannot be read is started afresh, which costs a look at the
files already here (they are checked by sha256, never fetched again), not a download.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import FormatError, StorageError
from fleetlog.storage.files import write_atomic
from fleetlog.wire.query import check_component

__all__ = [
    "ARCHIVE_RECORD",
    "COMPLETE",
    "CUT",
    "LOCK_NAME",
    "MISSING",
    "PARTIAL",
    "ArchiveLock",
    "ArchivedFile",
    "ArchivedSession",
    "VehicleRecord",
    "check_vehicle_dir",
    "collector_running",
    "load_record",
    "save_record",
    "session_bytes",
    "vehicle_dirs",
]

ARCHIVE_RECORD = ".fleetlog-archive.json"
LOCK_NAME = ".fleetlog-collect.lock"
#: a session's states in the archive
COMPLETE = "complete"
CUT = "cut"
PARTIAL = "partial"
MISSING = "missing"
_FORMAT = 1
#: a record larger than this is not read (a vehicle with tens of thousands of sessions
#: stays far below)
_MAX_RECORD = 256 << 20
_PART_SUFFIXES = (".part",)


@dataclass
class ArchivedFile:
    """A file of a session on shore, verified against the vehicle's sha256."""

    size: int
    sha256: str


@dataclass
class ArchivedSession:
    """What the archive holds of one session, and what the vehicle said of it.

    Attributes:
        name: the session directory's name.
        state: :data:`COMPLETE`, :data:`CUT`, :data:`PARTIAL` or :data:`MISSING`.
        vehicle_state: its metadata's state on the vehicle (``open``, ``closed``, ``cut``),
            None for a session without metadata (real pLogger's).
        files: the files on shore, verified.
        remote: the vehicle's files and sizes when it last listed them.
        on_vehicle: the vehicle listed it last time.
        completed: when it was complete (or cut) on shore.
        acked: when the vehicle acknowledged it (its retention may then delete it).
        pruned: when the vehicle's retention deleted it at the collector's request.
    """

    name: str
    state: str = MISSING
    vehicle_state: str | None = None
    files: dict[str, ArchivedFile] = field(default_factory=dict)
    remote: dict[str, int] = field(default_factory=dict)
    on_vehicle: bool = True
    completed: float | None = None
    acked: float | None = None
    pruned: float | None = None

    @property
    def done(self) -> bool:
        """Every file the vehicle listed is here, verified (complete or cut)."""
        return self.state in (COMPLETE, CUT)

    @property
    def remote_size(self) -> int:
        """Bytes the vehicle listed."""
        return sum(self.remote.values())

    def as_json(self) -> dict[str, Any]:
        """Return the record's JSON object."""
        return {
            "state": self.state,
            "vehicle_state": self.vehicle_state,
            "files": {n: {"size": f.size, "sha256": f.sha256} for n, f in self.files.items()},
            "remote": dict(self.remote),
            "on_vehicle": self.on_vehicle,
            "completed": self.completed,
            "acked": self.acked,
            "pruned": self.pruned,
        }

    @classmethod
    def from_json(cls, name: str, obj: Any) -> ArchivedSession:
        """Read one session's record.

        Raises:
            FormatError: not the shape :meth:`as_json` writes.
        """
        if not isinstance(obj, dict):
            msg = f"archive record of {name!r} is not an object"
            raise FormatError(msg)
        files: dict[str, ArchivedFile] = {}
        for fname, item in _dict(obj.get("files")).items():
            item = _dict(item)
            size, digest = item.get("size"), item.get("sha256")
            if isinstance(size, int) and isinstance(digest, str):
                files[fname] = ArchivedFile(size, digest)
        remote = {n: s for n, s in _dict(obj.get("remote")).items() if isinstance(s, int)}
        state = obj.get("state")
        vstate = obj.get("vehicle_state")
        return cls(
            name,
            state if state in (COMPLETE, CUT, PARTIAL, MISSING) else MISSING,
            vstate if isinstance(vstate, str) else None,
            files,
            remote,
            obj.get("on_vehicle") is not False,
            _time(obj.get("completed")),
            _time(obj.get("acked")),
            _time(obj.get("pruned")),
        )


def _dict(value: Any) -> dict[str, Any]:
    return value if isinstance(value, dict) else {}


def _flight(obj: dict[str, Any]) -> dict[str, Any]:
    """Keep what an in-flight entry may hold: a session, how, and finite figures."""
    out: dict[str, Any] = {k: obj[k] for k in ("session", "how") if isinstance(obj.get(k), str)}
    for key in ("since", "here", "size"):
        value = _time(obj.get(key))
        if value is not None:
            out[key] = int(value) if isinstance(obj[key], int) else value
    return out


def _time(value: Any) -> float | None:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return None
    try:
        number = float(value)
    except OverflowError:  # an integer too large for a float
        return None
    return number if math.isfinite(number) else None


@dataclass
class VehicleRecord:
    """The collector's record of one vehicle (one directory of the archive).

    Attributes:
        vehicle: the vehicle (the directory's name, ``VEHICLE@ZID`` for a second process).
        seen: when its liveliness token was last seen up.
        up: whether it was up when the record was written.
        sessions: per session, what is on shore.
        in_flight: what is being fetched now: ``{"session", "how", "since"}`` objects.
        error: the last error talking to it, if the last attempt failed.
        received: bytes received from it by the collector, in all.
        updated: when the record was written.
    """

    vehicle: str
    seen: float | None = None
    up: bool = False
    sessions: dict[str, ArchivedSession] = field(default_factory=dict)
    in_flight: list[dict[str, Any]] = field(default_factory=list)
    error: str | None = None
    received: int = 0
    updated: float | None = None

    def session(self, name: str) -> ArchivedSession:
        """Return the record of a session, made empty if it has none."""
        found = self.sessions.get(name)
        if found is None:
            found = self.sessions[name] = ArchivedSession(name)
        return found

    def to_bytes(self) -> bytes:
        """Return the record's file contents."""
        obj = {
            "format": _FORMAT,
            "vehicle": self.vehicle,
            "seen": self.seen,
            "up": self.up,
            "updated": self.updated,
            "error": self.error,
            "received": self.received,
            "in_flight": self.in_flight,
            "sessions": {n: s.as_json() for n, s in sorted(self.sessions.items())},
        }
        return json.dumps(obj, indent=1, allow_nan=False).encode() + b"\n"

    @classmethod
    def from_bytes(cls, vehicle: str, data: bytes) -> VehicleRecord:
        """Read a record.

        Raises:
            FormatError: not a record this fleetlog writes.
        """
        try:
            obj = json.loads(data)
        except (ValueError, RecursionError) as err:
            msg = f"archive record of {vehicle} is not JSON: {str(err)[:80]}"
            raise FormatError(msg) from None
        if not isinstance(obj, dict) or obj.get("format") != _FORMAT:
            msg = f"archive record of {vehicle} is not of format {_FORMAT}"
            raise FormatError(msg)
        sessions = {
            name: ArchivedSession.from_json(name, item)
            for name, item in _dict(obj.get("sessions")).items()
        }
        error = obj.get("error")
        received = obj.get("received")
        flights = obj.get("in_flight")
        return cls(
            vehicle,
            _time(obj.get("seen")),
            obj.get("up") is True,
            sessions,
            [_flight(f) for f in flights if isinstance(f, dict)]
            if isinstance(flights, list)
            else [],
            error if isinstance(error, str) else None,
            received if isinstance(received, int) else 0,
            _time(obj.get("updated")),
        )


def load_record(directory: Path) -> VehicleRecord | None:
    """Read ``directory/.fleetlog-archive.json``; None if there is none.

    Raises:
        StorageError: it exists but cannot be read.
        FormatError: it is not a record this fleetlog reads.
    """
    path = directory / ARCHIVE_RECORD
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        return None
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror or err}"
        raise StorageError(msg) from err
    try:
        with os.fdopen(fd, "rb") as file:
            data = file.read(_MAX_RECORD + 1)
    except OSError as err:
        msg = f"cannot read {path}: {err.strerror or err}"
        raise StorageError(msg) from err
    if len(data) > _MAX_RECORD:
        msg = f"{path} is larger than {_MAX_RECORD} bytes"
        raise FormatError(msg)
    return VehicleRecord.from_bytes(directory.name, data)


def save_record(directory: Path, record: VehicleRecord) -> None:
    """Replace ``directory/.fleetlog-archive.json`` atomically and durably.

    Raises:
        StorageError: it cannot be written.
    """
    write_atomic(directory / ARCHIVE_RECORD, record.to_bytes())


def vehicle_dirs(archive: Path) -> list[Path]:
    """Return the vehicle directories of an archive (those with a record), sorted.

    Raises:
        StorageError: the archive cannot be listed.
    """
    try:
        with os.scandir(archive) as it:
            found = [
                Path(e.path)
                for e in it
                if e.is_dir(follow_symlinks=False) and os.path.isfile(Path(e.path, ARCHIVE_RECORD))
            ]
    except OSError as err:
        msg = f"cannot list the archive {archive}: {err.strerror or err}"
        raise StorageError(msg) from err
    return sorted(found)


def session_bytes(directory: Path) -> tuple[int, int]:
    """Return the bytes of a session directory on shore: (complete files, ``.part`` files)."""
    done = partial = 0
    try:
        with os.scandir(directory) as it:
            for entry in it:
                try:
                    st = entry.stat(follow_symlinks=False)
                except OSError:
                    continue
                if not stat.S_ISREG(st.st_mode) or entry.name.endswith(".part.json"):
                    continue
                if entry.name.endswith(_PART_SUFFIXES):
                    partial += st.st_size
                else:
                    done += st.st_size
    except OSError:
        pass
    return done, partial


class ArchiveLock:
    """The lock of the one collector running on an archive (held until :meth:`release`).

    Args:
        archive: the archive directory (created if missing).

    Raises:
        StorageError: another collector holds it, or the archive cannot be created.
    """

    def __init__(self, archive: Path) -> None:
        path = archive / LOCK_NAME
        if archive.exists() and not archive.is_dir():
            msg = f"the archive {archive} is not a directory"
            raise StorageError(msg)
        try:
            archive.mkdir(parents=True, exist_ok=True)
            self._fd: int | None = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as err:
            msg = f"cannot use the archive {archive}: {err.strerror or err}"
            raise StorageError(msg) from err
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._fd)
            self._fd = None
            msg = f"another fleetlog collect is running on {archive}"
            raise StorageError(msg) from None
        except OSError:
            pass  # no flock on this file system: one collector per archive is then on trust

    def release(self) -> None:
        """Let another collector run on the archive."""
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


def collector_running(archive: Path) -> bool:
    """Return True if a collector holds the archive's lock now."""
    try:
        fd = os.open(archive / LOCK_NAME, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)
    return False


def check_vehicle_dir(name: str) -> str:
    """Return ``name`` if it can be a directory of the archive.

    Raises:
        FormatError: it is not a single path component (a hostile vehicle name).
    """
    check_component(name, "vehicle")
    if name.startswith("."):
        msg = f"vehicle name {name!r} would be a hidden directory"
        raise FormatError(msg)
    return name
