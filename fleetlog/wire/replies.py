"""The query services' replies: JSON shapes both sides read and write (docs/wire.md).

Pure code, no zenoh: file-range metadata, session lists (split over replies of about
:data:`REPLY_TARGET` bytes), and the latest session; the remote grep's JSON lines are in
:mod:`fleetlog.wire.grep_lines`. Every decoder checks each field's presence and type
(:mod:`fleetlog.wire.json_fields`) and raises :class:`FormatError` naming it, so a reply
from a peer that lies is refused, never half-read. The requests these answer are in
:mod:`fleetlog.wire.query`, which re-exports every name here.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.moos.recording_modes import MAX_NOTES, MAX_TAGS, check_note, check_tag
from fleetlog.wire.json_fields import dump_json, load_object, optional_field, required_field
from fleetlog.wire.keys import check_component
from fleetlog.wire.version import WIRE_VERSION, version_of

__all__ = [
    "REPLY_TARGET",
    "SERVER",
    "FileInfo",
    "FileMeta",
    "LatestInfo",
    "SessionInfo",
    "sessions_by_server",
    "sessions_from_json",
    "sessions_to_json",
]

#: the parameter every service takes, and the field of a reply that names who answered:
#: only the process with this Zenoh id answers
SERVER = "server"
#: how much JSON a sessions or grep reply carries before the next one starts
REPLY_TARGET = 256 << 10


@dataclass(frozen=True, slots=True)
class FileMeta:
    """What a file reply says about the bytes it carries (its attachment, JSON).

    Attributes:
        offset: where the bytes start.
        length: how many bytes the reply carries (fewer than asked at the end of the file).
        size: the file's size when it was read.
        mtime: its modification time (seconds since the epoch).
        complete: the file is no longer being written.
        sha256: the hex sha256 of the whole file, when asked for and the file is complete.
    """

    offset: int
    length: int
    size: int
    mtime: float
    complete: bool
    sha256: str | None = None

    def to_json(self) -> bytes:
        """Return the attachment bytes."""
        return dump_json(
            {
                "offset": self.offset,
                "length": self.length,
                "size": self.size,
                "mtime": self.mtime,
                "complete": self.complete,
                "sha256": self.sha256,
            }
        )

    @classmethod
    def from_json(cls, data: bytes | str) -> FileMeta:
        """Read the attachment.

        Raises:
            FormatError: not the shape above.
        """
        what = "file reply meta"
        obj = load_object(data, what)
        return cls(
            required_field(obj, "offset", int, what),
            required_field(obj, "length", int, what),
            required_field(obj, "size", int, what),
            float(required_field(obj, "mtime", (int, float), what)),
            required_field(obj, "complete", bool, what),
            optional_field(obj, "sha256", str, what),
        )


@dataclass(frozen=True, slots=True)
class FileInfo:
    """One file of a session."""

    name: str
    size: int
    mtime: float

    def as_json(self) -> dict[str, Any]:
        """Return the JSON object."""
        return {"name": self.name, "size": self.size, "mtime": self.mtime}


@dataclass(frozen=True, slots=True)
class SessionInfo:
    """One session as the ``sessions`` service describes it.

    Attributes:
        name: the directory name (pLogger's root, e.g. ``MOOSLog_3_2_2025_____09_05_07``).
        files: its regular files, by name.
        complete: no longer being written.
        stamp: the time in the name, ``YYYY-MM-DDTHH:MM:SS`` (local or UTC, as pLogger
            named it), or None for a name without one.
        alog: the alog's file name, or None.
        start: LOGSTART from the alog's banner (seconds since the epoch, or warped).
        duration: the last entry's time since LOGSTART.
        vehicle: the MOOS community that wrote it: the ``DB_TIME`` source ``MOOSDB_<v>``, the
            ``._moos`` Community, or the serving vehicle.
        variables: how many distinct variables the alog holds.
        state: from the session metadata: ``open``, ``closed``, or ``cut`` (its recorder
            died with it open); None for a session without metadata (real pLogger's).
        synced: whether the recording host's clock was synchronised when the session
            opened (session metadata); None when unknown.
        mission_id: the mission it is a part of and ``part`` its number (session metadata;
            the parts of a split share the mission id); None without metadata.
        notes: its notes and ``tags`` its tags (session metadata; at most 64 each, as the
            recorder keeps them; a reply's others are left out).
        opened: when the recorder opened this directory (session metadata): a split's later
            part keeps its mission's LOGSTART as ``start``, so this is when the part began.
    """

    name: str
    files: tuple[FileInfo, ...]
    complete: bool
    stamp: str | None = None
    alog: str | None = None
    start: float | None = None
    duration: float | None = None
    vehicle: str | None = None
    variables: int | None = None
    state: str | None = None
    synced: bool | None = None
    mission_id: str | None = None
    part: int | None = None
    notes: Mapping[str, str] = field(default_factory=dict)
    tags: tuple[str, ...] = ()
    opened: float | None = None

    @property
    def size(self) -> int:
        """The total size of the files."""
        return sum(f.size for f in self.files)

    def as_json(self) -> dict[str, Any]:
        """Return the JSON object."""
        return {
            "name": self.name,
            "complete": self.complete,
            "stamp": self.stamp,
            "alog": self.alog,
            "start": self.start,
            "duration": self.duration,
            "vehicle": self.vehicle,
            "variables": self.variables,
            "state": self.state,
            "synced": self.synced,
            "mission_id": self.mission_id,
            "part": self.part,
            "notes": dict(self.notes),
            "tags": list(self.tags),
            "opened": self.opened,
            "size": self.size,
            "files": [f.as_json() for f in self.files],
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> SessionInfo:
        """Read one session.

        Raises:
            FormatError: not the shape above.
        """
        what = "session"
        files = []
        for item in required_field(obj, "files", list, what):
            if not isinstance(item, dict):
                msg = "session: a file entry is not an object"
                raise FormatError(msg)
            files.append(
                FileInfo(
                    check_component(required_field(item, "name", str, "file"), "file"),
                    required_field(item, "size", int, "file"),
                    float(required_field(item, "mtime", (int, float), "file")),
                )
            )
        start = _time(optional_field(obj, "start", (int, float), what))
        duration = _time(optional_field(obj, "duration", (int, float), what))
        opened = _time(optional_field(obj, "opened", (int, float), what))
        return cls(
            check_component(required_field(obj, "name", str, what), "session"),
            tuple(files),
            required_field(obj, "complete", bool, what),
            optional_field(obj, "stamp", str, what),
            optional_field(obj, "alog", str, what),
            start,
            duration,
            optional_field(obj, "vehicle", str, what),
            optional_field(obj, "variables", int, what),
            optional_field(obj, "state", str, what),
            optional_field(obj, "synced", bool, what),
            optional_field(obj, "mission_id", str, what),
            optional_field(obj, "part", int, what),
            _notes(obj.get("notes")),
            _tags(obj.get("tags")),
            opened,
        )


def _time(value: float | None) -> float | None:
    """A time from a reply as a float; None if absent or not finite.

    NaN, inf, or an integer too large for a float: a peer's reply is shown, not trusted.
    """
    if value is None:
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _notes(value: Any) -> dict[str, str]:
    """The notes of a reply: string keys and values within the recorder's bounds, 64 at most."""
    if not isinstance(value, dict):
        return {}
    kept = {
        k: v
        for k, v in itertools.islice(value.items(), MAX_NOTES)
        if isinstance(k, str) and isinstance(v, str) and check_note(k, v) is None
    }
    return kept


def _tags(value: Any) -> tuple[str, ...]:
    if not isinstance(value, list):
        return ()
    return tuple(t for t in value[:MAX_TAGS] if isinstance(t, str) and check_tag(t) is None)


def sessions_to_json(
    vehicle: str,
    sessions: Sequence[SessionInfo],
    *,
    server: str | None = None,
    recorder: str | None = None,
) -> list[bytes]:
    """Return the ``sessions`` replies: ``{"vehicle", "sessions": [...], "more"}`` objects.

    Sessions are split over several replies of about :data:`REPLY_TARGET` bytes, so a vehicle
    with thousands of sessions never sends one huge reply; ``more`` is false on the last.
    Each reply also names the answering process (``server``, its Zenoh id) and, when that
    process is the vehicle's recorder, ``recorder`` (the same id).
    """
    replies: list[bytes] = []
    batch: list[dict[str, Any]] = []
    size = 0
    who = {"server": server, "recorder": recorder}
    wire = {"wire": WIRE_VERSION}
    for info in sessions:
        obj = info.as_json()
        batch.append(obj)
        size += len(dump_json(obj))
        if size >= REPLY_TARGET:
            replies.append(
                dump_json({"vehicle": vehicle, **who, "sessions": batch, "more": True, **wire})
            )
            batch, size = [], 0
    replies.append(dump_json({"vehicle": vehicle, **who, "sessions": batch, "more": False, **wire}))
    return replies


def sessions_by_server(replies: Sequence[bytes]) -> dict[str | None, list[SessionInfo]]:
    """Read the ``sessions`` replies back, in order, each answering process's apart.

    Two processes that serve the same vehicle (two recorders after a partition heals) both
    answer one query; their replies interleave, and each reply names its ``server``.

    Raises:
        FormatError: a reply is not the shape above, or a process's last one is missing.
    """
    out: dict[str | None, list[SessionInfo]] = {}
    more: dict[str | None, bool] = {}
    for data in replies:
        obj = load_object(data, "sessions reply")
        server = optional_field(obj, SERVER, str, "sessions reply")
        found = out.setdefault(server, [])
        for item in required_field(obj, "sessions", list, "sessions reply"):
            if not isinstance(item, dict):
                msg = "sessions reply: a session is not an object"
                raise FormatError(msg)
            found.append(SessionInfo.from_json(item))
        more[server] = required_field(obj, "more", bool, "sessions reply")
    if not out or any(more.values()):
        msg = "the sessions replies ended before the last one (the link dropped?)"
        raise FormatError(msg)
    return out


def sessions_from_json(replies: Sequence[bytes]) -> list[SessionInfo]:
    """Read the ``sessions`` replies of one answering process back, in order.

    Raises:
        FormatError: a reply is not the shape above, the last one is missing, or the replies
            come from two processes (see :func:`sessions_by_server`).
    """
    found = sessions_by_server(replies)
    if len(found) > 1:
        msg = f"the sessions replies come from {len(found)} processes"
        raise FormatError(msg)
    return next(iter(found.values()))


@dataclass(frozen=True, slots=True)
class LatestInfo:
    """The ``latest`` reply.

    Attributes:
        vehicle: the serving vehicle.
        session: the latest session's name, or None when the log root holds none.
        writing: it is still being written.
        how: how it was found: ``recorder`` (the one being recorded), ``hint`` (the
            ``.LastOpenedMOOSLogDirectory`` file) or ``newest`` (by its time stamp).
        hint: the directory the hint file names, as written, if one was read.
        start: the session's LOGSTART, if its alog has one.
        server: the Zenoh id of the process that answered.
        recorder: the Zenoh id of the vehicle's recorder, when the recorder answered (None
            for ``fleetlog serve``).
        synced: whether the recording host's clock was synchronised when the session
            opened (session metadata), None when unknown.
    """

    vehicle: str
    session: str | None
    writing: bool
    how: str
    hint: str | None = None
    start: float | None = None
    server: str | None = None
    recorder: str | None = None
    wire: int = WIRE_VERSION
    synced: bool | None = None

    def to_json(self) -> bytes:
        """Return the reply bytes."""
        return dump_json(
            {
                "vehicle": self.vehicle,
                "session": self.session,
                "writing": self.writing,
                "how": self.how,
                "hint": self.hint,
                "start": self.start,
                "server": self.server,
                "recorder": self.recorder,
                "wire": self.wire,
                "synced": self.synced,
            }
        )

    @classmethod
    def from_json(cls, data: bytes | str) -> LatestInfo:
        """Read the reply.

        Raises:
            FormatError: not the shape above.
        """
        what = "latest reply"
        obj = load_object(data, what)
        start = optional_field(obj, "start", (int, float), what)
        session = optional_field(obj, "session", str, what)
        return cls(
            required_field(obj, "vehicle", str, what),
            None if session is None else check_component(session, "session"),
            required_field(obj, "writing", bool, what),
            required_field(obj, "how", str, what),
            optional_field(obj, "hint", str, what),
            None if start is None else float(start),
            optional_field(obj, "server", str, what),
            optional_field(obj, "recorder", str, what),
            version_of(obj),
            optional_field(obj, "synced", bool, what),
        )
