"""The query services' protocol: keys, request parameters, reply shapes (docs/wire.md).

Pure code, no zenoh: keys and parameter strings in, validated requests out. The reply shapes
live in :mod:`fleetlog.wire.replies` and :mod:`fleetlog.wire.grep_lines`, the parameter codec
in :mod:`fleetlog.wire.parameters`; all are re-exported here. The vehicle side
(:mod:`fleetlog.query.server`) and the shore side (:mod:`fleetlog.shore.client`) both use it,
so the two can never disagree.

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

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import chunk_to_name, name_to_chunk
from fleetlog.wire.grep_lines import (
    GrepEnd,
    GrepHeader,
    GrepRecord,
    decode_grep_lines,
    encode_grep_line,
)
from fleetlog.wire.keys import SERVICE, check_component, service_key
from fleetlog.wire.parameters import (
    flag_parameter,
    format_parameters,
    int_parameter,
    parse_parameters,
    split_server,
    with_server,
)
from fleetlog.wire.replies import (
    REPLY_TARGET,
    SERVER,
    FileInfo,
    FileMeta,
    LatestInfo,
    SessionInfo,
    sessions_by_server,
    sessions_from_json,
    sessions_to_json,
)

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

#: what a range request gets when it names no length: measured here, 1 MB replies with a few
#: in flight reach 300-500 MB/s between processes
DEFAULT_RANGE = 1 << 20
#: the largest range a request may ask for: a single huge reply silently failed (STYLE §5)
MAX_RANGE = 4 << 20
DEFAULT_GREP_LIMIT = 100_000
MAX_GREP_LIMIT = 10_000_000
#: bounds on what a request may carry, so a garbled one costs nothing to refuse
MAX_PATTERNS = 64
MAX_OFFSET = 1 << 50

_FLOAT = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")


# --------------------------------------------------------------------------------------------
# Names and keys


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
    return SessionsRequest(session, flag_parameter(params, "brief"))


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
    offset = int_parameter(params, "offset", 0, 0, MAX_OFFSET)
    length = int_parameter(params, "length", DEFAULT_RANGE, 0, 1 << 53)
    if length > MAX_RANGE:
        msg = f"parameter 'length' asks for {length} bytes; a range holds at most {MAX_RANGE}"
        raise FormatError(msg)
    return FileRequest(offset, length, flag_parameter(params, "sha256"))


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
        int_parameter(params, "limit", DEFAULT_GREP_LIMIT, 1, MAX_GREP_LIMIT),
    )
