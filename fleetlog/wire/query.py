"""The query services' protocol: keys, request parameters, reply shapes (docs/wire.md).

Pure code, no zenoh: keys and parameter strings in, validated requests out; reply objects to
and from JSON. The vehicle side (:mod:`fleetlog.query.server`) and the shore side
(:mod:`fleetlog.shore.client`) both use it, so the two can never disagree.

Every service lives under ``<root>/V/@fleetlog/``:

* ``latest`` — the latest session and whether it is still being written;
* ``sessions`` — every session with its files (``?session=NAME`` for one, ``?brief=1`` for
  names, files and sizes only, without reading the logs);
* ``file/<session>/<name>`` — a byte range of one file (``?offset=O;length=N``, ``N`` at most
  4 MiB; ``?sha256=1`` adds the sha256 of a complete file);
* ``grep/<session>`` — the entries of a session's alog filtered by variables, sources and a
  time window, up to a limit, streamed back as JSON lines in bounded replies.

Every service also takes ``server=ZID``: only the process with that Zenoh id answers (two
recorders of one vehicle after a partition heals both serve the same keys; the shore then
asks each by its id). ``latest`` and ``sessions`` replies say which process answered.

Session and file names are escaped into key chunks as every MOOS name is
(:func:`fleetlog.moos.patterns.name_to_chunk`) and must be single path components: not
empty, not ``.`` or ``..``, no ``/`` and no NUL. Parameter values are percent-decoded
(``%3B`` for ``;``, ``%7C`` for ``|``, ``%25`` for ``%``); list parameters separate their
items with ``|``, as Zenoh's selector parameters do.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any
from urllib.parse import quote, unquote_to_bytes

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import chunk_to_name, name_to_chunk
from fleetlog.wire.keys import SERVICE, service_key

__all__ = [
    "DEFAULT_GREP_LIMIT",
    "DEFAULT_RANGE",
    "FILE",
    "GREP",
    "LATEST",
    "MAX_GREP_LIMIT",
    "MAX_RANGE",
    "RECORDER_TOKEN",
    "REPLY_TARGET",
    "SERVER",
    "SERVE_TOKEN",
    "SESSIONS",
    "FileInfo",
    "FileMeta",
    "FileRequest",
    "GrepEnd",
    "GrepHeader",
    "GrepRecord",
    "GrepRequest",
    "LatestInfo",
    "SessionInfo",
    "SessionsRequest",
    "TimeBound",
    "check_component",
    "decode_grep_lines",
    "encode_grep_line",
    "file_key",
    "format_parameters",
    "grep_key",
    "parse_file_request",
    "parse_grep_request",
    "parse_parameters",
    "parse_service_parts",
    "parse_sessions_request",
    "session_key",
    "sessions_by_server",
    "sessions_from_json",
    "sessions_to_json",
    "split_server",
    "with_server",
]

#: the liveliness token of a recorder
RECORDER_TOKEN = "recorder"
#: the liveliness token of ``fleetlog serve``
SERVE_TOKEN = "serve"
#: the service names (the key chunk after ``@fleetlog``)
LATEST = "latest"
SESSIONS = "sessions"
FILE = "file"
GREP = "grep"
#: the parameter every service takes: only the process with this Zenoh id answers
SERVER = "server"

#: what a range request gets when it names no length: measured here, 1 MB replies with a few
#: in flight reach 300-500 MB/s between processes
DEFAULT_RANGE = 1 << 20
#: the largest range a request may ask for: a single huge reply silently failed (STYLE §5)
MAX_RANGE = 4 << 20
#: how much JSON a sessions or grep reply carries before the next one starts
REPLY_TARGET = 256 << 10
DEFAULT_GREP_LIMIT = 100_000
MAX_GREP_LIMIT = 10_000_000
#: bounds on what a request may carry, so a garbled one costs nothing to refuse
MAX_PARAMETERS = 8192
MAX_NAME_BYTES = 255
MAX_PATTERNS = 64
MAX_OFFSET = 1 << 50

_PERCENT = re.compile(r"%(?![0-9A-Fa-f]{2})")
_INT = re.compile(r"[0-9]{1,16}")
_ZID = re.compile(r"[0-9a-f]{1,32}")
_FLOAT = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


# --------------------------------------------------------------------------------------------
# Names and keys


def check_component(name: str, what: str) -> str:
    r"""Check that a session or file name is one plain path component.

    Args:
        name: the name, already unescaped from its key chunk.
        what: ``"session"`` or ``"file"``, for the message.

    Returns:
        The name unchanged.

    Raises:
        FormatError: the name is empty, ``.`` or ``..``, holds ``/``, ``\`` or NUL, or is
            longer than 255 bytes; each could reach outside the session.
    """
    if not name:
        reason = "is empty"
    elif name in (".", ".."):
        reason = "is a relative directory"
    elif "/" in name:
        reason = "holds '/' (only one path component is allowed)"
    elif "\\" in name:
        reason = "holds '\\' (only one path component is allowed)"
    elif "\x00" in name:
        reason = "holds a NUL character"
    elif len(name.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES:
        reason = f"is longer than {MAX_NAME_BYTES} bytes"
    else:
        return name
    msg = f"{what} name {name[:80]!r} {reason}"
    raise FormatError(msg)


def session_key(root: str, vehicle: str, service: str) -> str:
    """Return the key of a vehicle-wide service (``latest``, ``sessions``)."""
    return service_key(root, vehicle, service)


def file_key(root: str, vehicle: str, session: str, name: str) -> str:
    """Return the key of one file of a session (``.../@fleetlog/file/<session>/<name>``).

    Raises:
        FormatError: a name is not a single path component (see :func:`check_component`).
    """
    session_chunk = name_to_chunk(check_component(session, "session"))
    name_chunk = name_to_chunk(check_component(name, "file"))
    return service_key(root, vehicle, FILE, session_chunk, name_chunk)


def grep_key(root: str, vehicle: str, session: str) -> str:
    """Return the key of the remote grep over a session (``.../@fleetlog/grep/<session>``).

    Raises:
        FormatError: the session name is not a single path component.
    """
    chunk = name_to_chunk(check_component(session, "session"))
    return service_key(root, vehicle, GREP, chunk)


def parse_service_parts(key: str) -> tuple[str, tuple[str, ...]]:
    """Return the service and its unescaped names from a query's key.

    The query may hold wildcards before ``@fleetlog`` (``fleet/*/@fleetlog/latest`` asks every
    vehicle), never after it: a file or a session is always named exactly.

    Args:
        key: the query's key expression.

    Returns:
        ``(service, names)``, e.g. ``("file", ("MOOSLog_3_2_2025_____09_05_07", "x.alog"))``.

    Raises:
        FormatError: no ``@fleetlog`` chunk, an unknown service, the wrong number of names,
            a wildcard or a chunk that is not an escaped name, or a name that is not a
            single path component.
    """
    chunks = key.split("/")
    if SERVICE not in chunks:
        msg = f"key {key[:200]!r} names no {SERVICE} service"
        raise FormatError(msg)
    tail = chunks[chunks.index(SERVICE) + 1 :]
    if not tail:
        msg = f"key {key[:200]!r} names no service after {SERVICE}"
        raise FormatError(msg)
    for chunk in tail:
        if chunk in ("*", "**") or "$*" in chunk:
            msg = f"a service and its names must be given exactly, not with the wildcard {chunk!r}"
            raise FormatError(msg)
    service, args = tail[0], tail[1:]
    arity = {LATEST: (), SESSIONS: (), FILE: ("session", "file"), GREP: ("session",)}
    if service not in arity:
        msg = f"unknown service {service[:80]!r}; expected one of {', '.join(arity)}"
        raise FormatError(msg)
    whats = arity[service]
    if len(args) != len(whats):
        wanted = " and ".join(whats) if whats else "nothing"
        msg = f"the {service} service takes {wanted} after its name, got {len(args)} chunk(s)"
        raise FormatError(msg)
    names: list[str] = []
    for chunk, what in zip(args, whats, strict=True):
        try:
            name = chunk_to_name(chunk)
        except FormatError as err:
            msg = f"the {what} chunk {chunk[:80]!r} is not an escaped name: {err.reason}"
            raise FormatError(msg) from None
        names.append(check_component(name, what))
    return service, tuple(names)


# --------------------------------------------------------------------------------------------
# Parameters


def parse_parameters(text: str, known: Iterable[str]) -> dict[str, str]:
    """Split selector parameters ``a=1;b=x|y`` into a dict, percent-decoding the values.

    Args:
        text: the selector's parameters, as received.
        known: the parameter names the service accepts.

    Returns:
        name → decoded value (a flag written without ``=`` has the value ``""``).

    Raises:
        FormatError: the text is too long, a parameter is unknown or given twice, or a value
            holds a ``%`` that is not followed by two hex digits.
    """
    if len(text) > MAX_PARAMETERS:
        msg = f"the parameters are {len(text)} characters long; at most {MAX_PARAMETERS}"
        raise FormatError(msg)
    allowed = frozenset(known)
    out: dict[str, str] = {}
    for item in text.split(";") if text else ():
        if not item:
            continue
        name, _, raw = item.partition("=")
        if name not in allowed:
            expected = ", ".join(sorted(allowed)) or "none"
            msg = f"unknown parameter {name[:40]!r}; this service takes {expected}"
            raise FormatError(msg)
        if name in out:
            msg = f"parameter {name!r} is given twice"
            raise FormatError(msg)
        out[name] = _unquote(name, raw)
    return out


def _unquote(name: str, raw: str) -> str:
    if _PERCENT.search(raw):
        msg = f"parameter {name!r} holds a '%' that is not followed by two hex digits"
        raise FormatError(msg)
    # Percent escapes spell UTF-8 bytes; undecodable ones survive as surrogate escapes (and
    # so does a raw one, which only a local caller can pass: Zenoh's selectors are UTF-8).
    value = unquote_to_bytes(raw.encode("utf-8", "surrogateescape")).decode(
        "utf-8", "surrogateescape"
    )
    if "\x00" in value:
        msg = f"parameter {name!r} holds a NUL character"
        raise FormatError(msg)
    return value


def _quote(value: str) -> str:
    return quote(value.encode("utf-8", "surrogateescape"), safe="*?@:,.-_+~")


def format_parameters(values: Mapping[str, str | int | float | bool | Sequence[str] | None]) -> str:
    """Return selector parameters for a request; the inverse of :func:`parse_parameters`.

    None and False are left out, True becomes ``name=1``, a sequence joins its quoted items
    with ``|``.
    """
    items: list[str] = []
    for name, value in values.items():
        if value is None or value is False:
            continue
        if value is True:
            items.append(f"{name}=1")
        elif isinstance(value, str):
            items.append(f"{name}={_quote(value)}")
        elif isinstance(value, int | float):
            items.append(f"{name}={value!r}")
        else:
            items.append(f"{name}=" + "|".join(_quote(v) for v in value))
    return ";".join(items)


def _int(params: Mapping[str, str], name: str, default: int, low: int, high: int) -> int:
    text = params.get(name)
    if text is None:
        return default
    if not _INT.fullmatch(text):
        msg = f"parameter {name!r} must be a whole number of at most 16 digits, not {text[:40]!r}"
        raise FormatError(msg)
    value = int(text)
    if not low <= value <= high:
        msg = f"parameter {name!r} must be between {low} and {high}, not {value}"
        raise FormatError(msg)
    return value


def _flag(params: Mapping[str, str], name: str) -> bool:
    text = params.get(name)
    if text is None or text in ("0", "false"):
        return False
    if text in ("", "1", "true"):
        return True
    msg = f"parameter {name!r} must be 1 or 0, not {text[:40]!r}"
    raise FormatError(msg)


def split_server(text: str) -> tuple[str | None, str]:
    """Take the ``server=ZID`` parameter out of a request's parameters.

    Returns:
        The Zenoh id asked for (None if the request names none) and the other parameters,
        for the service's own parser.

    Raises:
        FormatError: the parameters are too long, or the id is not 1-32 lower-case hex
            digits.
    """
    if len(text) > MAX_PARAMETERS:
        msg = f"the parameters are {len(text)} characters long; at most {MAX_PARAMETERS}"
        raise FormatError(msg)
    if SERVER not in text:
        return None, text
    server: str | None = None
    rest: list[str] = []
    for item in text.split(";"):
        name, _, value = item.partition("=")
        if name != SERVER:
            rest.append(item)
            continue
        if server is not None:
            msg = f"parameter {SERVER!r} is given twice"
            raise FormatError(msg)
        if not _ZID.fullmatch(value):
            msg = f"parameter {SERVER!r} must be a Zenoh id (hex), not {value[:40]!r}"
            raise FormatError(msg)
        server = value
    return server, ";".join(rest)


def with_server(parameters: str, server: str | None) -> str:
    """Return ``parameters`` with ``server=ZID`` added (unchanged for None)."""
    if server is None:
        return parameters
    return f"{parameters};{SERVER}={server}" if parameters else f"{SERVER}={server}"


# --------------------------------------------------------------------------------------------
# Requests


@dataclass(frozen=True, slots=True)
class SessionsRequest:
    """What a ``sessions`` query asks for.

    Attributes:
        session: one session only, or None for all.
        brief: names, files, sizes and completeness only; nothing read from the logs.
    """

    session: str | None = None
    brief: bool = False

    def parameters(self) -> str:
        """Return the selector parameters of this request."""
        return format_parameters({"session": self.session, "brief": self.brief})


def parse_sessions_request(text: str) -> SessionsRequest:
    """Parse a ``sessions`` query's parameters (``session``, ``brief``).

    Raises:
        FormatError: an unknown or garbled parameter, or a session name that is not a single
            path component.
    """
    params = parse_parameters(text, ("session", "brief"))
    session = params.get("session")
    if session is not None:
        check_component(session, "session")
    return SessionsRequest(session, _flag(params, "brief"))


@dataclass(frozen=True, slots=True)
class FileRequest:
    """A byte range of a file.

    Attributes:
        offset: the first byte.
        length: how many bytes at most (1 MiB by default, at most 4 MiB; 0 asks for the
            meta only).
        sha256: also return the sha256 of the whole file if it is complete.
    """

    offset: int = 0
    length: int = DEFAULT_RANGE
    sha256: bool = False

    def parameters(self) -> str:
        """Return the selector parameters of this request."""
        return format_parameters(
            {"offset": self.offset, "length": self.length, "sha256": self.sha256}
        )


def parse_file_request(text: str) -> FileRequest:
    """Parse a ``file`` query's parameters (``offset``, ``length``, ``sha256``).

    Raises:
        FormatError: an unknown or garbled parameter, or a range longer than 4 MiB.
    """
    params = parse_parameters(text, ("offset", "length", "sha256"))
    offset = _int(params, "offset", 0, 0, MAX_OFFSET)
    length = _int(params, "length", DEFAULT_RANGE, 0, 1 << 53)
    if length > MAX_RANGE:
        msg = f"parameter 'length' asks for {length} bytes; a range holds at most {MAX_RANGE}"
        raise FormatError(msg)
    return FileRequest(offset, length, _flag(params, "sha256"))


@dataclass(frozen=True, slots=True)
class TimeBound:
    """One end of a time window: seconds since LOGSTART, or seconds since the epoch.

    Written ``12.5`` (an offset) or ``@1750334690.5`` (absolute) in a request.
    """

    value: float
    absolute: bool = False

    def text(self) -> str:
        """Return the bound as a request writes it."""
        return ("@" if self.absolute else "") + repr(self.value)

    def offset(self, logstart: float | None) -> float:
        """Return the bound as seconds since LOGSTART.

        Raises:
            FormatError: an absolute bound on a log without LOGSTART.
        """
        if not self.absolute:
            return self.value
        if logstart is None:
            msg = "an absolute time needs the log's LOGSTART, and this log has none"
            raise FormatError(msg)
        return self.value - logstart

    @classmethod
    def parse(cls, text: str, name: str = "time") -> TimeBound:
        """Read ``12.5`` or ``@1750334690.5``.

        Raises:
            FormatError: not a finite number.
        """
        absolute = text.startswith("@")
        body = text[1:] if absolute else text
        if not _FLOAT.fullmatch(body) or not math.isfinite(float(body)):
            msg = (
                f"parameter {name!r} must be seconds since LOGSTART (12.5) or since the epoch "
                f"(@1750334690.5), not {text[:40]!r}"
            )
            raise FormatError(msg)
        return cls(float(body), absolute)


@dataclass(frozen=True, slots=True)
class GrepRequest:
    """A remote aloggrep/alogclip over a session's alog.

    An entry is sent when its variable matches one of ``variables`` (MOOS globs; none means
    every variable), its source matches one of ``sources`` (globs tried on the whole source
    column and on the process name before ``:``/``@``; none means every source), and its time
    lies in ``[start, end]``; at most ``limit`` entries are sent, in file order.
    """

    variables: tuple[str, ...] = ()
    sources: tuple[str, ...] = ()
    start: TimeBound | None = None
    end: TimeBound | None = None
    limit: int = DEFAULT_GREP_LIMIT

    def parameters(self) -> str:
        """Return the selector parameters of this request."""
        return format_parameters(
            {
                "var": self.variables or None,
                "source": self.sources or None,
                "from": self.start.text() if self.start else None,
                "to": self.end.text() if self.end else None,
                "limit": self.limit,
            }
        )


def _patterns(params: Mapping[str, str], name: str) -> tuple[str, ...]:
    text = params.get(name)
    if text is None:
        return ()
    items = tuple(text.split("|"))
    if len(items) > MAX_PATTERNS:
        msg = f"parameter {name!r} holds {len(items)} patterns; at most {MAX_PATTERNS}"
        raise FormatError(msg)
    for item in items:
        if not item or any(c.isspace() for c in item):
            msg = f"parameter {name!r}: a pattern must be non-empty and without blanks"
            raise FormatError(msg)
    return items


def parse_grep_request(text: str) -> GrepRequest:
    """Parse a ``grep`` query's parameters (``var``, ``source``, ``from``, ``to``, ``limit``).

    Raises:
        FormatError: an unknown or garbled parameter, a blank pattern, too many patterns, a
            time that is not a number, or a limit out of range.
    """
    params = parse_parameters(text, ("var", "source", "from", "to", "limit"))
    start = TimeBound.parse(params["from"], "from") if "from" in params else None
    end = TimeBound.parse(params["to"], "to") if "to" in params else None
    if start and end and start.absolute == end.absolute and start.value > end.value:
        msg = f"parameter 'from' ({start.text()}) is after 'to' ({end.text()})"
        raise FormatError(msg)
    return GrepRequest(
        _patterns(params, "var"),
        _patterns(params, "source"),
        start,
        end,
        _int(params, "limit", DEFAULT_GREP_LIMIT, 1, MAX_GREP_LIMIT),
    )


# --------------------------------------------------------------------------------------------
# Replies


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
        )


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
    for info in sessions:
        obj = info.as_json()
        batch.append(obj)
        size += len(_dump(obj))
        if size >= REPLY_TARGET:
            replies.append(_dump({"vehicle": vehicle, **who, "sessions": batch, "more": True}))
            batch, size = [], 0
    replies.append(_dump({"vehicle": vehicle, **who, "sessions": batch, "more": False}))
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
    """

    vehicle: str
    session: str | None
    writing: bool
    how: str
    hint: str | None = None
    start: float | None = None
    server: str | None = None
    recorder: str | None = None

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
