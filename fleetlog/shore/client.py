"""The shore side of the query services: which vehicles are up, their sessions, files, grep.

Example::

    from fleetlog.shore.client import FleetClient
    from fleetlog.transport.session import SessionOptions

    with FleetClient.open(SessionOptions(connect=("tcp/10.0.0.5:7447",))) as fleet:
        print(fleet.vehicles())                      # {"alpha": {"recorder"}, ...}
        latest = fleet.latest("alpha")
        for entry in fleet.grep("alpha", latest.session, GrepRequest(variables=("NAV_*",))):
            print(entry.offset, entry.key, entry.value)

Every call names the vehicle; a vehicle that does not answer gives a :class:`QueryError` that
names the vehicles that are up. A Zenoh query that reaches no queryable returns at once with
no replies, so "no answer" is reported as soon as it is known, not after a timeout.
"""

from __future__ import annotations

from collections.abc import Iterator
from types import TracebackType

from fleetlog.errors import FormatError, QueryError
from fleetlog.moos.alog import BinaryRef, Entry, parse_binary_ref
from fleetlog.transport.queries import PendingQuery, ZenohSession, start_query
from fleetlog.transport.services import live_vehicles, refusal_hint
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import (
    DEFAULT_ROOT,
    check_root,
    fleet_service_selector,
    parse_service_key,
    service_key,
)
from fleetlog.wire.query import (
    DEFAULT_RANGE,
    LATEST,
    RECORDER_TOKEN,
    SERVE_TOKEN,
    SESSIONS,
    FileMeta,
    FileRequest,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    LatestInfo,
    SessionInfo,
    SessionsRequest,
    decode_grep_lines,
    file_key,
    grep_key,
    sessions_from_json,
)

__all__ = ["FleetClient", "GrepStream", "PendingRange", "TransientQueryError", "record_entry"]

#: error replies that say "not now" rather than "never": a client may retry them
_TRANSIENT_REPLIES = ("the log server is busy", "the log server is closing")


class TransientQueryError(QueryError):
    """Nobody answered, or the vehicle said it is busy or closing: worth retrying later."""


def _reply_error(vehicle: str, text: str) -> QueryError:
    msg = f"vehicle {vehicle}: {text}"
    if text.startswith(_TRANSIENT_REPLIES):
        return TransientQueryError(msg)
    return QueryError(msg)


def record_entry(record: GrepRecord) -> Entry:
    """Turn a grep record back into the :class:`~fleetlog.moos.alog.Entry` a local read gives.

    Raises:
        FormatError: a double or binary record whose text is not one.
    """
    value: float | str | BinaryRef = record.text
    if record.kind == "d":
        try:
            value = float(record.text)
        except ValueError:
            msg = f"grep record {record.key}: {record.text!r} is not a double"
            raise FormatError(msg) from None
    elif record.kind == "b":
        ref = parse_binary_ref(record.text)
        if ref is None:
            msg = f"grep record {record.key}: {record.text[:60]!r} is not a binary reference"
            raise FormatError(msg)
        value = ref
    return Entry(record.offset, record.key, record.source, value, record.text, record.lineno)


class PendingRange:
    """A range request in flight; :meth:`result` waits for its one reply."""

    def __init__(
        self,
        client: FleetClient,
        vehicle: str,
        selector: str,
        offset: int,
        length: int,
        handler: PendingQuery,
    ) -> None:
        self.client = client
        self.vehicle = vehicle
        self.selector = selector
        self.offset = offset
        self.length = length
        self._handler = handler

    def result(self) -> tuple[bytes, FileMeta]:
        """Return the range's bytes and meta.

        Raises:
            QueryError: an error reply, no reply (timeout, or nobody serves the file), or a
                reply without its meta.
        """
        found: tuple[bytes, FileMeta] | None = None
        error: str | None = None
        for reply in self._handler:
            if reply.error is not None:
                error = reply.error
                continue
            if found is not None:
                continue  # a second server answering the same key: keep the first
            if reply.attachment is None:
                msg = f"vehicle {self.vehicle}: a file reply came without its meta"
                raise QueryError(msg)
            try:
                meta = FileMeta.from_json(reply.attachment)
            except FormatError as err:
                msg = f"vehicle {self.vehicle}: {err}"
                raise QueryError(msg) from None
            found = (reply.payload, meta)
        if found is not None:
            return found
        if error is not None:
            raise _reply_error(self.vehicle, error)
        raise self.client.no_answer(self.vehicle, self.selector)


class GrepStream:
    """The entries of a remote grep, as they arrive.

    Iterate it for :class:`GrepRecord` objects (or use :meth:`entries`); :attr:`header` is set
    before the first record, :attr:`end` after the last.

    Raises:
        QueryError: (while iterating) an error reply, or the stream ended without its end
            record (the link dropped, or the query timed out).
    """

    def __init__(
        self,
        client: FleetClient,
        vehicle: str,
        selector: str,
        handler: PendingQuery,
    ) -> None:
        self.client = client
        self.vehicle = vehicle
        self.selector = selector
        self.header: GrepHeader | None = None
        self.end: GrepEnd | None = None
        self._handler = handler

    def __iter__(self) -> Iterator[GrepRecord]:
        got_any = False
        for reply in self._handler:
            if reply.error is not None:
                raise _reply_error(self.vehicle, reply.error)
            got_any = True
            try:
                items = decode_grep_lines(reply.payload)
            except FormatError as err:
                msg = f"vehicle {self.vehicle}: {err}"
                raise QueryError(msg) from None
            for item in items:
                if isinstance(item, GrepRecord):
                    yield item
                elif isinstance(item, GrepHeader):
                    self.header = item
                else:
                    self.end = item
        if not got_any:
            raise self.client.no_answer(self.vehicle, self.selector)
        if self.end is None:
            msg = (
                f"vehicle {self.vehicle}: the grep answer ended early (the link dropped or the"
                f" query timed out after {self.client.grep_timeout:g} s; see --timeout)"
            )
            raise QueryError(msg)

    def entries(self) -> Iterator[Entry]:
        """Yield the records as :class:`~fleetlog.moos.alog.Entry` objects."""
        for record in self:
            yield record_entry(record)


class FleetClient:
    """Asks the fleet's vehicles about their logs over one Zenoh session.

    Args:
        session: an open Zenoh session, kept as :attr:`zenoh` (closed by :meth:`close` only
            if ``own`` is True).
        root: the key root.
        timeout: seconds to wait for an ordinary answer.
        grep_timeout: seconds a grep may take in all.
        own: close the session with the client.

    Raises:
        FormatError: the key root is not usable.
    """

    def __init__(
        self,
        session: ZenohSession,
        *,
        root: str = DEFAULT_ROOT,
        timeout: float = 10.0,
        grep_timeout: float = 300.0,
        own: bool = False,
    ) -> None:
        self.zenoh = session
        self.root = check_root(root)
        self.timeout = timeout
        self.grep_timeout = grep_timeout
        self._own = own

    @classmethod
    def open(
        cls,
        options: SessionOptions | None = None,
        *,
        root: str = DEFAULT_ROOT,
        timeout: float = 10.0,
        grep_timeout: float = 300.0,
    ) -> FleetClient:
        """Open a Zenoh session and a client on it.

        Raises:
            TransportError: the session cannot be opened.
        """
        session = open_session(options or SessionOptions())
        return cls(session, root=root, timeout=timeout, grep_timeout=grep_timeout, own=True)

    def close(self) -> None:
        """Close the session if the client opened it."""
        if self._own:
            self.zenoh.close()
            self._own = False

    def __enter__(self) -> FleetClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- who is up

    def vehicles(self, timeout: float = 2.0) -> dict[str, set[str]]:
        """Return the vehicles up now: ``{vehicle: {"recorder", "serve"}}`` (liveliness).

        Raises:
            TransportError: the liveliness query failed.
        """
        return live_vehicles(self.zenoh, self.root, (RECORDER_TOKEN, SERVE_TOKEN), timeout)

    def no_answer(self, vehicle: str, selector: str, action: str = "query") -> TransientQueryError:
        """Build the error for a query nobody answered, naming the vehicles that are up."""
        try:
            up = sorted(self.vehicles())
        except Exception:  # the error is about the first failure, not this one
            up = []
        key = selector.split("?")[0]
        if vehicle in up:
            msg = (
                f"vehicle {vehicle!r} is up but nothing answered {key!r}"
                " (a recorder that does not serve its logs, or the link dropped)"
            )
        elif up:
            msg = f"vehicle {vehicle!r} is not up; vehicles up: {', '.join(up)}"
        else:
            msg = (
                f"vehicle {vehicle!r} is not up, and no vehicle is (no fleetlog recorder or"
                " serve token is reachable: check --connect / --mode)"
            )
        return TransientQueryError(msg + refusal_hint(self.zenoh, action, key))

    def nobody_hint(self) -> str:
        """What to add to "no vehicle is up" when a router may have refused the question."""
        selector = fleet_service_selector(self.root, RECORDER_TOKEN)
        return refusal_hint(self.zenoh, "liveliness query", selector)

    def require(self, vehicle: str) -> None:
        """Check that a vehicle is up.

        Raises:
            QueryError: it is not; the message names the vehicles that are.
        """
        if vehicle not in self.vehicles():
            tokens = service_key(self.root, vehicle, RECORDER_TOKEN)
            raise self.no_answer(vehicle, tokens, "liveliness query")

    # -- queries

    def _get(self, selector: str, timeout: float) -> PendingQuery:
        return start_query(self.zenoh, selector, timeout=timeout)

    def _samples(self, vehicle: str, selector: str, timeout: float | None = None) -> list[bytes]:
        payloads: list[bytes] = []
        error: str | None = None
        for reply in self._get(selector, timeout or self.timeout):
            if reply.error is None:
                payloads.append(reply.payload)
            elif error is None:
                error = reply.error
        if error is not None:
            raise _reply_error(vehicle, error)
        if not payloads:
            raise self.no_answer(vehicle, selector)
        return payloads

    def latest(self, vehicle: str) -> LatestInfo:
        """Return a vehicle's latest session.

        Raises:
            QueryError: no answer or an error reply.
        """
        payloads = self._samples(vehicle, service_key(self.root, vehicle, LATEST))
        try:
            return LatestInfo.from_json(payloads[0])
        except FormatError as err:
            msg = f"vehicle {vehicle}: {err}"
            raise QueryError(msg) from None

    def latest_all(self) -> dict[str, LatestInfo]:
        """Ask every vehicle for its latest session at once: ``{vehicle: info}``.

        Vehicles whose reply is an error or unreadable are left out.

        Raises:
            TransportError: the query failed.
        """
        selector = fleet_service_selector(self.root, LATEST)
        out: dict[str, LatestInfo] = {}
        for reply in self._get(selector, self.timeout):
            if reply.error is not None:
                continue
            try:
                vehicle, _ = parse_service_key(self.root, reply.key)
                out[vehicle] = LatestInfo.from_json(reply.payload)
            except FormatError:
                continue
        return out

    def sessions(
        self, vehicle: str, *, brief: bool = False, timeout: float | None = None
    ) -> list[SessionInfo]:
        """Return a vehicle's sessions, oldest first.

        Raises:
            QueryError: no answer, an error reply, or replies that are not a session list.
        """
        return self._sessions(vehicle, SessionsRequest(None, brief), timeout)

    def session(self, vehicle: str, name: str, *, brief: bool = True) -> SessionInfo:
        """Return one session of a vehicle.

        Raises:
            QueryError: no such session, no answer, or an error reply.
        """
        found = self._sessions(vehicle, SessionsRequest(name, brief), None)
        if len(found) != 1:
            msg = f"vehicle {vehicle}: expected one session {name!r}, got {len(found)}"
            raise QueryError(msg)
        return found[0]

    def _sessions(
        self, vehicle: str, request: SessionsRequest, timeout: float | None
    ) -> list[SessionInfo]:
        selector = service_key(self.root, vehicle, SESSIONS)
        params = request.parameters()
        if params:
            selector += "?" + params
        payloads = self._samples(vehicle, selector, timeout or max(self.timeout, 60.0))
        try:
            return sessions_from_json(payloads)
        except FormatError as err:
            msg = f"vehicle {vehicle}: {err}"
            raise QueryError(msg) from None

    def request_range(
        self,
        vehicle: str,
        session: str,
        name: str,
        offset: int,
        length: int = DEFAULT_RANGE,
        *,
        sha256: bool = False,
        timeout: float | None = None,
    ) -> PendingRange:
        """Send a range request without waiting; call ``result()`` on what it returns.

        Raises:
            FormatError: a name is not a single path component.
            TransportError: the query could not be sent.
        """
        request = FileRequest(offset, length, sha256)
        selector = file_key(self.root, vehicle, session, name) + "?" + request.parameters()
        handler = self._get(selector, timeout or self.timeout)
        return PendingRange(self, vehicle, selector, offset, length, handler)

    def read_range(
        self,
        vehicle: str,
        session: str,
        name: str,
        offset: int,
        length: int = DEFAULT_RANGE,
        *,
        sha256: bool = False,
    ) -> tuple[bytes, FileMeta]:
        """Read a byte range of a file of a vehicle's session.

        Raises:
            QueryError: no answer, or an error reply (no such file, a path outside the log
                root, a range past the end...).
        """
        return self.request_range(vehicle, session, name, offset, length, sha256=sha256).result()

    def grep(self, vehicle: str, session: str, request: GrepRequest | None = None) -> GrepStream:
        """Start a remote grep over a session's alog; iterate the result for its records.

        Raises:
            FormatError: the session name is not a single path component.
            TransportError: the query could not be sent.
        """
        req = request or GrepRequest()
        selector = grep_key(self.root, vehicle, session) + "?" + req.parameters()
        return GrepStream(self, vehicle, selector, self._get(selector, self.grep_timeout))
