"""The session metadata file ``<session>/.fleetlog-session.json`` (docs/wire.md).

Pure: the schema, its JSON form, and the ``PLOGGER_GAP`` entry text that marks a loss in the
alog (docs/compat.md). Writing, locking and marking cut sessions are in
:mod:`fleetlog.storage.metafile`.

A session's file is ``open`` while a recorder writes it, ``closed`` after a clean close and
``cut`` once a later recorder found it ``open`` with no recorder alive; ``closed`` and ``cut``
files never change again.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.json_fields import parse_json

__all__ = [
    "ACKS_NAME",
    "CLOSED",
    "CUT",
    "MAX_GAPS",
    "MAX_GAP_VARS",
    "MAX_META_BYTES",
    "META_FORMAT",
    "META_NAME",
    "OPEN",
    "STATES",
    "Gap",
    "SessionMeta",
]

META_NAME = ".fleetlog-session.json"
#: the collectors' acknowledgements, one JSON line per acknowledged session, in the log root
ACKS_NAME = ".fleetlog-acks.jsonl"
META_FORMAT = 1
OPEN = "open"
CLOSED = "closed"
CUT = "cut"
STATES = (OPEN, CLOSED, CUT)
#: gaps kept in a session's file (the alog's PLOGGER_GAP entries hold every one)
MAX_GAPS = 256
#: a metadata file larger than this is not read (it cannot be one the recorder wrote)
MAX_META_BYTES = 1 << 20
#: variables named in one gap (the others are counted in the total only)
MAX_GAP_VARS = 16
_MOOS_TEXT = re.compile(r"[,=;:\x00-\x1f]")


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class Gap:
    """Where samples were lost, and why (a ``PLOGGER_GAP`` entry and a ``gaps`` item).

    Attributes:
        time: when the loss was noticed (seconds since the epoch).
        reason: ``crash``, ``disk-full``, ``read-only``, ``removed``, ``write-error``,
            ``no-session``, ``dropped`` (a DROP publisher's samples lost on the way) or
            ``unreadable`` (a key that names no variable).
        lost: samples lost, or None when nobody can know (a crash).
        start: the first moment of the loss, if known.
        end: the last moment of the loss, if known.
        variables: samples lost per variable, for at most 16 variables.
        session: the session the loss belongs to when that is another one (a crash's cut
            session), else empty.
    """

    time: float
    reason: str
    lost: int | None
    start: float | None = None
    end: float | None = None
    variables: Mapping[str, int] = field(default_factory=dict)
    session: str = ""

    def moos_text(self) -> str:
        """Return the value of the ``PLOGGER_GAP`` alog entry.

        ``reason=disk-full,lost=120,from=1750000000.250,to=1750000003.500,vars=NAV_X:60;NAV_Y:60``
        — MOOS's comma-separated ``key=value`` pairs, as in ``PLOGGER_STATUS``; ``lost=?``
        when unknown; ``session=`` names a crashed session. Names holding ``,=;:`` are left
        out of ``vars`` (they would break the pairs).
        """
        parts = [f"reason={self.reason}", f"lost={'?' if self.lost is None else self.lost}"]
        if self.start is not None:
            parts.append(f"from={self.start:.3f}")
        if self.end is not None:
            parts.append(f"to={self.end:.3f}")
        if self.session and not _MOOS_TEXT.search(self.session):
            parts.append(f"session={self.session}")
        names = [f"{k}:{v}" for k, v in self.variables.items() if not _MOOS_TEXT.search(k)]
        if names:
            parts.append("vars=" + ";".join(names))
        return ",".join(parts)

    def as_json(self) -> dict[str, Any]:
        """Return the ``gaps`` item."""
        return {
            "time": self.time,
            "reason": self.reason,
            "lost": self.lost,
            "from": self.start,
            "to": self.end,
            "vars": dict(self.variables),
            "session": self.session,
        }

    @classmethod
    def from_json(cls, obj: Any) -> Gap:
        """Read a ``gaps`` item.

        Raises:
            FormatError: not the shape above.
        """
        if not isinstance(obj, dict):
            msg = "session metadata: a gap is not an object"
            raise FormatError(msg)
        variables = obj.get("vars") or {}
        if not isinstance(variables, dict) or not all(
            isinstance(k, str) and isinstance(v, int) for k, v in variables.items()
        ):
            msg = "session metadata: a gap's 'vars' is not an object of counts"
            raise FormatError(msg)
        time: Any = obj.get("time")
        reason = obj.get("reason")
        lost = obj.get("lost")
        if not _finite(time) or not isinstance(reason, str):
            msg = "session metadata: a gap lacks its 'time' or 'reason'"
            raise FormatError(msg)
        if lost is not None and (not isinstance(lost, int) or isinstance(lost, bool)):
            msg = "session metadata: a gap's 'lost' is not a count"
            raise FormatError(msg)
        start: Any = obj.get("from")
        end: Any = obj.get("to")
        return cls(
            float(time),
            reason,
            lost,
            float(start) if _finite(start) else None,
            float(end) if _finite(end) else None,
            variables,
            str(obj.get("session") or ""),
        )


@dataclass(frozen=True)
class SessionMeta:
    """The contents of ``.fleetlog-session.json`` (docs/wire.md, "Session metadata").

    Attributes:
        state: ``open``, ``closed`` or ``cut``.
        vehicle: the vehicle recorded.
        session: the session directory's name.
        recorder: the recording process's Zenoh id (empty when unknown).
        fleetlog: the recorder's fleetlog version.
        opened: when the session opened (seconds since the epoch).
        logstart: the session's LOGSTART.
        closed: when it closed cleanly, or when it was found cut; None while open.
        updated: when this version of the file was written.
        mission_id: ties the parts of a split mission together.
        part: the part number within the mission (1 without splits).
        counters: the recorder's counters for this session alone.
        gaps: where samples were lost (at most :data:`MAX_GAPS`; the alog has every one).
        clock: the clock's synchronisation state at open.
        notes: free-form key/value notes.
        tags: free-form tags.
        host: the recording host's name, ``pid`` its process id and ``boot`` the host's boot
            id: they tell whether the recorder is alive where a directory lock is not
            available (some network file systems).
    """

    state: str
    vehicle: str
    session: str
    recorder: str
    fleetlog: str
    opened: float
    logstart: float
    closed: float | None = None
    updated: float | None = None
    mission_id: str = ""
    part: int = 1
    counters: Mapping[str, int] = field(default_factory=dict)
    gaps: tuple[Gap, ...] = ()
    clock: Mapping[str, Any] = field(default_factory=dict)
    notes: Mapping[str, str] = field(default_factory=dict)
    tags: tuple[str, ...] = ()
    host: str = ""
    pid: int = 0
    boot: str = ""

    def with_state(self, state: str, when: float) -> SessionMeta:
        """Return the final version: ``closed`` or ``cut`` at ``when``.

        A cut session keeps ``updated``: the last time its own recorder was heard of.
        """
        return replace(
            self, state=state, closed=when, updated=when if state == CLOSED else self.updated
        )

    def as_json(self) -> dict[str, Any]:
        """Return the JSON object, in the order docs/wire.md lists the fields."""
        return {
            "format": META_FORMAT,
            "state": self.state,
            "vehicle": self.vehicle,
            "session": self.session,
            "recorder": self.recorder,
            "fleetlog": self.fleetlog,
            "opened": self.opened,
            "closed": self.closed,
            "updated": self.updated,
            "logstart": self.logstart,
            "mission_id": self.mission_id,
            "part": self.part,
            "counters": dict(self.counters),
            "gaps": [g.as_json() for g in self.gaps],
            "clock": dict(self.clock),
            "notes": dict(self.notes),
            "tags": list(self.tags),
            "host": self.host,
            "pid": self.pid,
            "boot": self.boot,
        }

    def to_bytes(self) -> bytes:
        """Return the file's bytes (one JSON object, indented for people, newline at the end)."""
        return (json.dumps(self.as_json(), indent=1, allow_nan=False) + "\n").encode()

    @classmethod
    def from_bytes(cls, data: bytes) -> SessionMeta:
        """Read a metadata file.

        Raises:
            FormatError: too large, not JSON, another format, or a field of the wrong type.
        """
        if len(data) > MAX_META_BYTES:
            msg = f"session metadata is {len(data)} bytes long; at most {MAX_META_BYTES}"
            raise FormatError(msg)
        try:
            obj = parse_json(data)
        except ValueError as err:
            msg = f"session metadata is not JSON: {err}"
            raise FormatError(msg) from None
        if not isinstance(obj, dict):
            msg = "session metadata is not a JSON object"
            raise FormatError(msg)
        if obj.get("format") != META_FORMAT:
            msg = f"session metadata has format {obj.get('format')!r}; this fleetlog reads 1"
            raise FormatError(msg)
        state = obj.get("state")
        if state not in STATES:
            msg = f"session metadata has state {state!r}; expected open, closed or cut"
            raise FormatError(msg)
        return cls(
            state=state,
            vehicle=_text(obj, "vehicle"),
            session=_text(obj, "session"),
            recorder=_text(obj, "recorder"),
            fleetlog=_text(obj, "fleetlog"),
            opened=_number(obj, "opened"),
            logstart=_number(obj, "logstart"),
            closed=_number(obj, "closed", optional=True),
            updated=_number(obj, "updated", optional=True),
            mission_id=_text(obj, "mission_id"),
            part=int(_number(obj, "part", default=1)),
            counters=_mapping(obj, "counters", int),
            gaps=tuple(Gap.from_json(g) for g in _list(obj, "gaps")),
            clock=_mapping(obj, "clock", object),
            notes=_mapping(obj, "notes", str),
            tags=tuple(t for t in _list(obj, "tags") if isinstance(t, str)),
            host=_text(obj, "host"),
            pid=int(_number(obj, "pid", default=0)),
            boot=_text(obj, "boot"),
        )


def _text(obj: Mapping[str, Any], name: str) -> str:
    value = obj.get(name, "")
    if value is None:
        return ""
    if not isinstance(value, str):
        msg = f"session metadata: field {name!r} is not a string"
        raise FormatError(msg)
    return value


def _number(
    obj: Mapping[str, Any], name: str, *, optional: bool = False, default: float | None = None
) -> Any:
    value = obj.get(name)
    if value is None and (optional or default is not None):
        return default
    if not _finite(value):
        msg = f"session metadata: field {name!r} is missing or not a finite number"
        raise FormatError(msg)
    return value


def _list(obj: Mapping[str, Any], name: str) -> list[Any]:
    value = obj.get(name) or []
    if not isinstance(value, list):
        msg = f"session metadata: field {name!r} is not a list"
        raise FormatError(msg)
    return value


def _mapping(obj: Mapping[str, Any], name: str, kind: type) -> dict[str, Any]:
    value = obj.get(name) or {}
    if not isinstance(value, dict) or not all(
        isinstance(v, kind) and not (kind is int and isinstance(v, bool)) for v in value.values()
    ):
        msg = f"session metadata: field {name!r} is not an object of {kind.__name__} values"
        raise FormatError(msg)
    return value
