"""The query services' replies: JSON shapes both sides read and write (docs/wire.md).

Pure code, no zenoh: file-range metadata, session lists (split over replies of about
:data:`REPLY_TARGET` bytes), the latest session, and the remote grep's JSON lines. Every
decoder checks each field's presence and type and raises :class:`FormatError` naming it, so
a reply from a peer that lies is refused, never half-read. The requests these answer are in
:mod:`fleetlog.wire.query`, which re-exports every name here.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.moos.recording_modes import MAX_NOTES, MAX_TAGS, check_note, check_tag
from fleetlog.wire.keys import check_component
from fleetlog.wire.version import WIRE_VERSION, version_of

__all__ = [
    "REPLY_TARGET",
    "SERVER",
    "FileInfo",
    "FileMeta",
    "GrepEnd",
    "GrepHeader",
    "GrepRecord",
    "LatestInfo",
    "SessionInfo",
    "decode_grep_lines",
    "encode_grep_line",
    "sessions_by_server",
    "sessions_from_json",
    "sessions_to_json",
]

#: the parameter every service takes, and the field of a reply that names who answered:
#: only the process with this Zenoh id answers
SERVER = "server"
#: how much JSON a sessions or grep reply carries before the next one starts
REPLY_TARGET = 256 << 10


def _get(obj: Mapping[str, Any], name: str, kind: type | tuple[type, ...], what: str) -> Any:
    value = obj.get(name)
    if not isinstance(value, kind) or (isinstance(value, bool) and kind in (int, float)):
        msg = f"{what}: field {name!r} is missing or has the wrong type"
        raise FormatError(msg)
    return value


def _opt(obj: Mapping[str, Any], name: str, kind: type | tuple[type, ...], what: str) -> Any:
    return None if obj.get(name) is None else _get(obj, name, kind, what)


def _load(data: bytes | str, what: str) -> dict[str, Any]:
    try:
        obj = json.loads(data)
    except ValueError as err:
        msg = f"{what} is not JSON: {err}"
        raise FormatError(msg) from None
    if not isinstance(obj, dict):
        msg = f"{what} is not a JSON object"
        raise FormatError(msg)
    return obj


def _dump(obj: object) -> bytes:
    # ensure_ascii keeps surrogate-escaped bytes as \udcXX, which json.loads gives back.
    return json.dumps(obj, separators=(",", ":")).encode("ascii")


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
        return _dump(
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
        obj = _load(data, what)
        return cls(
            _get(obj, "offset", int, what),
            _get(obj, "length", int, what),
            _get(obj, "size", int, what),
            float(_get(obj, "mtime", (int, float), what)),
            _get(obj, "complete", bool, what),
            _opt(obj, "sha256", str, what),
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
        for item in _get(obj, "files", list, what):
            if not isinstance(item, dict):
                msg = "session: a file entry is not an object"
                raise FormatError(msg)
            files.append(
                FileInfo(
                    check_component(_get(item, "name", str, "file"), "file"),
                    _get(item, "size", int, "file"),
                    float(_get(item, "mtime", (int, float), "file")),
                )
            )
        start = _opt(obj, "start", (int, float), what)
        duration = _opt(obj, "duration", (int, float), what)
        return cls(
            check_component(_get(obj, "name", str, what), "session"),
            tuple(files),
            _get(obj, "complete", bool, what),
            _opt(obj, "stamp", str, what),
            _opt(obj, "alog", str, what),
            None if start is None else float(start),
            None if duration is None else float(duration),
            _opt(obj, "vehicle", str, what),
            _opt(obj, "variables", int, what),
            _opt(obj, "state", str, what),
            _opt(obj, "synced", bool, what),
            _opt(obj, "mission_id", str, what),
            _opt(obj, "part", int, what),
            _notes(obj.get("notes")),
            _tags(obj.get("tags")),
        )


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
        size += len(_dump(obj))
        if size >= REPLY_TARGET:
            replies.append(
                _dump({"vehicle": vehicle, **who, "sessions": batch, "more": True, **wire})
            )
            batch, size = [], 0
    replies.append(_dump({"vehicle": vehicle, **who, "sessions": batch, "more": False, **wire}))
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
        obj = _load(data, "sessions reply")
        server = _opt(obj, SERVER, str, "sessions reply")
        found = out.setdefault(server, [])
        for item in _get(obj, "sessions", list, "sessions reply"):
            if not isinstance(item, dict):
                msg = "sessions reply: a session is not an object"
                raise FormatError(msg)
            found.append(SessionInfo.from_json(item))
        more[server] = _get(obj, "more", bool, "sessions reply")
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
        return _dump(
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
        obj = _load(data, what)
        start = _opt(obj, "start", (int, float), what)
        session = _opt(obj, "session", str, what)
        return cls(
            _get(obj, "vehicle", str, what),
            None if session is None else check_component(session, "session"),
            _get(obj, "writing", bool, what),
            _get(obj, "how", str, what),
            _opt(obj, "hint", str, what),
            None if start is None else float(start),
            _opt(obj, "server", str, what),
            _opt(obj, "recorder", str, what),
            version_of(obj),
            _opt(obj, "synced", bool, what),
        )


# -- grep: JSON lines, a header first and an end record last, entries in between


@dataclass(frozen=True, slots=True)
class GrepHeader:
    """The first line of a grep stream: how to read and print the entries.

    Attributes:
        session: the session.
        alog: the alog's file name.
        logstart: LOGSTART, or None when the banner is unusable.
        banner: the alog's banner lines, without newlines (aloggrep keeps them).
        time_decimals: decimals of the file's time column (3 essential-moos, 5 MOOS-IvP).
        mark_data_type: the file marks values ``D:``/``S:``.
    """

    session: str
    alog: str
    logstart: float | None
    banner: tuple[str, ...] = ()
    time_decimals: int = 5
    mark_data_type: bool = False


@dataclass(frozen=True, slots=True)
class GrepRecord:
    """One matching entry: time since LOGSTART, variable, source, type and value text.

    ``kind`` is ``d`` (double), ``s`` (string) or ``b`` (binary: ``text`` is the
    ``<MOOS_BINARY>`` reference); ``text`` is the value as written, without padding or
    MarkDataType marker; ``lineno`` is where the entry starts in the file.
    """

    offset: float
    key: str
    source: str
    kind: str
    text: str
    lineno: int


@dataclass(frozen=True, slots=True)
class GrepEnd:
    """The last line of a grep stream.

    Attributes:
        matched: entries sent.
        scanned: entries read.
        truncated: the limit stopped the scan before the end of the file.
        skipped: lines the reader could not use (see ``AlogReader.skipped``).
        cut: the file ended inside an entry (being written, or a crash).
    """

    matched: int
    scanned: int
    truncated: bool
    skipped: int = 0
    cut: bool = False


_KINDS = frozenset("dsb")


def encode_grep_line(item: GrepHeader | GrepRecord | GrepEnd) -> bytes:
    """Return one line of a grep stream, newline included."""
    obj: object
    if isinstance(item, GrepRecord):
        obj = [item.offset, item.key, item.source, item.kind, item.text, item.lineno]
    elif isinstance(item, GrepHeader):
        obj = {
            "header": True,
            "session": item.session,
            "alog": item.alog,
            "logstart": item.logstart,
            "banner": list(item.banner),
            "time_decimals": item.time_decimals,
            "mark_data_type": item.mark_data_type,
        }
    else:
        obj = {
            "end": True,
            "matched": item.matched,
            "scanned": item.scanned,
            "truncated": item.truncated,
            "skipped": item.skipped,
            "cut": item.cut,
        }
    return _dump(obj) + b"\n"


def _grep_record(obj: list[Any]) -> GrepRecord:
    if (
        len(obj) != 6
        or not isinstance(obj[0], int | float)
        or not all(isinstance(x, str) for x in obj[1:5])
        or obj[3] not in _KINDS
        or not isinstance(obj[5], int)
    ):
        msg = "grep reply: an entry is not [time, var, source, kind, text, line]"
        raise FormatError(msg)
    return GrepRecord(float(obj[0]), obj[1], obj[2], obj[3], obj[4], obj[5])


def decode_grep_lines(data: bytes) -> list[GrepHeader | GrepRecord | GrepEnd]:
    """Read one grep reply (several lines).

    Raises:
        FormatError: a line is not a header, an entry or an end record.
    """
    out: list[GrepHeader | GrepRecord | GrepEnd] = []
    for line in data.splitlines():
        if not line:
            continue
        try:
            obj = json.loads(line)
        except ValueError as err:
            msg = f"grep reply: a line is not JSON: {err}"
            raise FormatError(msg) from None
        if isinstance(obj, list):
            out.append(_grep_record(obj))
        elif isinstance(obj, dict) and obj.get("header") is True:
            what = "grep header"
            logstart = _opt(obj, "logstart", (int, float), what)
            banner = _get(obj, "banner", list, what)
            out.append(
                GrepHeader(
                    _get(obj, "session", str, what),
                    _get(obj, "alog", str, what),
                    None if logstart is None else float(logstart),
                    tuple(str(x) for x in banner),
                    _get(obj, "time_decimals", int, what),
                    _get(obj, "mark_data_type", bool, what),
                )
            )
        elif isinstance(obj, dict) and obj.get("end") is True:
            what = "grep end"
            out.append(
                GrepEnd(
                    _get(obj, "matched", int, what),
                    _get(obj, "scanned", int, what),
                    _get(obj, "truncated", bool, what),
                    _get(obj, "skipped", int, what),
                    _get(obj, "cut", bool, what),
                )
            )
        else:
            msg = "grep reply: a line is neither a header, an entry nor an end record"
            raise FormatError(msg)
    return out
