"""The shore side of the query services: which vehicles are up, their sessions, files, grep.

Example::

    from fleetlog.shore.client import FleetClient
    from fleetlog.transport.session import SessionOptions

    with FleetClient.open(SessionOptions(connect=("tcp/10.0.0.5:7447",))) as fleet:
        view = fleet.discover(expect=("alpha",))     # waits until alpha is seen (or 3 s)
        print(view.describe())                       # "2 vehicle(s) up: alpha, bravo ..."
        latest = fleet.latest("alpha")
        for entry in fleet.grep("alpha", latest.session, GrepRequest(variables=("NAV_*",))):
            print(entry.offset, entry.key, entry.value)

The client watches the fleet's liveliness tokens from the moment it opens
(:class:`~fleetlog.shore.discovery.Discovery`): :meth:`FleetClient.discover` waits until the
fleet is known instead of asking once and trusting the first answers. Every call names the
vehicle; a vehicle that does not answer gives a :class:`QueryError` that names the vehicles
that are up. A Zenoh query that reaches no queryable returns at once with no replies, so "no
answer" is reported as soon as it is known, not after a timeout.

Two processes may answer for one vehicle (two recorders after a partition heals; a recorder
and a ``fleetlog serve``): replies name their process (``server``, its Zenoh id), calls take
``server=`` to ask one of them, and a call that needs one answer raises
:class:`ConflictError` naming both instead of mixing them.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Mapping
from types import TracebackType
from typing import Any

from fleetlog.errors import FormatError, QueryError
from fleetlog.shore.answers import (
    ConflictError,
    GrepStream,
    PendingRange,
    TransientQueryError,
    reply_error,
)
from fleetlog.shore.control import ControlReply
from fleetlog.shore.discovery import QUIET, WAIT, Discovery, FleetView
from fleetlog.shore.status import VehicleStatus
from fleetlog.transport.queries import PendingQuery, ReplyItem, ZenohSession, start_query
from fleetlog.transport.services import refusal_hint
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.control import CONTROL, PRUNE
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
    SESSIONS,
    FileMeta,
    FileRequest,
    GrepRequest,
    LatestInfo,
    SessionInfo,
    SessionsRequest,
    file_key,
    grep_key,
    sessions_by_server,
    with_server,
)

__all__ = ["FleetClient"]


#: the recorder's status service
STATUS = "status"
#: how long a vehicle whose token is up may take to answer a first query (its queryables'
#: declarations can trail its token by a few milliseconds when it or the link just started)
_ANSWER_GRACE = 1.5


def _priority(selector: str) -> str:
    """A query's Zenoh priority by what it asks.

    Replies travel at their query's priority, so on a slow link commands and status overtake
    file ranges and greps (docs/deploy.md, "Slow links").
    """
    key = selector.split("?", 1)[0]
    if "/@fleetlog/file/" in key or "/@fleetlog/grep/" in key:
        return "bulk"
    if key.endswith(("/@fleetlog/control", "/@fleetlog/status", "/replay/control")):
        return "command"
    return "normal"


class FleetClient:
    """Asks the fleet's vehicles about their logs over one Zenoh session.

    Args:
        session: an open Zenoh session, kept as :attr:`zenoh` (closed by :meth:`close` only
            if ``own`` is True).
        root: the key root.
        timeout: seconds to wait for an ordinary answer.
        grep_timeout: seconds a grep may take in all.
        own: close the session with the client.
        wait: seconds :meth:`discover` waits for the fleet at most (``--wait``).
        quiet: seconds without news after which the fleet is taken as known.

    Raises:
        FormatError: the key root is not usable.
        TransportError: the liveliness subscription failed.
    """

    def __init__(
        self,
        session: ZenohSession,
        *,
        root: str = DEFAULT_ROOT,
        timeout: float = 10.0,
        grep_timeout: float = 300.0,
        own: bool = False,
        wait: float = WAIT,
        quiet: float = QUIET,
    ) -> None:
        self.zenoh = session
        self.root = check_root(root)
        self.timeout = timeout
        self.grep_timeout = grep_timeout
        self.wait = wait
        self._own = own
        try:
            self.discovery = Discovery(session, self.root, quiet=quiet)
        except BaseException:
            if own:
                session.close()
            raise

    @classmethod
    def open(
        cls,
        options: SessionOptions | None = None,
        *,
        root: str = DEFAULT_ROOT,
        timeout: float = 10.0,
        grep_timeout: float = 300.0,
        wait: float = WAIT,
    ) -> FleetClient:
        """Open a Zenoh session and a client on it.

        Raises:
            TransportError: the session cannot be opened.
        """
        session = open_session(options or SessionOptions())
        return cls(
            session, root=root, timeout=timeout, grep_timeout=grep_timeout, own=True, wait=wait
        )

    def close(self) -> None:
        """Stop watching the fleet; close the session if the client opened it."""
        self.discovery.close()
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

    def discover(self, expect: Iterable[str] = (), wait: float | None = None) -> FleetView:
        """Wait until the fleet is known; return who is up (see :mod:`fleetlog.shore.discovery`).

        Args:
            expect: vehicles to wait for: the wait ends as soon as all of them are up.
            wait: seconds at most, counted from when the client opened (default: ``wait``).
        """
        return self.discovery.wait(expect, self.wait if wait is None else wait)

    def vehicles(self) -> dict[str, set[str]]:
        """Return the vehicles up now: ``{vehicle: {"recorder", "serve"}}`` (liveliness).

        The first call waits until the fleet is known (:meth:`discover`).
        """
        if self.discovery.settled is None:
            self.discover()
        return {v: set(s) for v, s in self.discovery.current().items()}

    def no_answer(self, vehicle: str, selector: str, action: str = "query") -> TransientQueryError:
        """Build the error for a query nobody answered, naming the vehicles that are up."""
        try:
            up = sorted(self.discovery.current())
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

    def require(self, vehicle: str, wait: float | None = None) -> FleetView:
        """Wait until a vehicle is up (at most ``wait`` seconds); return the fleet seen.

        Raises:
            QueryError: it did not come up; the message names the vehicles that are.
        """
        view = self.discover((vehicle,), wait)
        if view.missing:
            tokens = service_key(self.root, vehicle, RECORDER_TOKEN)
            raise self.no_answer(vehicle, tokens, "liveliness query")
        return view

    # -- queries

    def _get(self, selector: str, timeout: float, payload: bytes | None = None) -> PendingQuery:
        return start_query(
            self.zenoh, selector, timeout=timeout, payload=payload, priority=_priority(selector)
        )

    def _replies(
        self,
        vehicle: str,
        selector: str,
        timeout: float | None = None,
        payload: bytes | None = None,
    ) -> list[ReplyItem]:
        """Run a query to one vehicle; return its good replies.

        Raises:
            QueryError: an error reply, or no reply at all.
        """
        deadline = time.monotonic() + _ANSWER_GRACE
        delay = 0.02
        while True:
            replies: list[ReplyItem] = []
            error: str | None = None
            for reply in self._get(selector, timeout or self.timeout, payload):
                if reply.error is None:
                    replies.append(reply)
                elif error is None:
                    error = reply.error
            if error is not None:
                raise reply_error(vehicle, error)
            if replies:
                return replies
            # Nothing answered. A vehicle whose token is up may not have its queryables known
            # here yet (they trail the token by milliseconds after a start or a reconnect).
            if vehicle not in self.discovery.current() or time.monotonic() + delay > deadline:
                raise self.no_answer(vehicle, selector)
            time.sleep(delay)
            delay = min(0.2, delay * 2)

    def _samples(self, vehicle: str, selector: str, timeout: float | None = None) -> list[bytes]:
        return [reply.payload for reply in self._replies(vehicle, selector, timeout)]

    # -- control

    def control(
        self,
        vehicle: str,
        request: Mapping[str, Any],
        *,
        replay: bool = False,
        timeout: float | None = None,
    ) -> list[ControlReply]:
        """Send a control request to a vehicle's recorder, or to the replay playing it.

        The request is ``{"cmd": NAME, ...arguments}`` (docs/wire.md, "Control"); each
        process that answers gives one reply (two recorders of one vehicle both act).

        Raises:
            QueryError: nothing answered, an error reply (a malformed request), or a reply
                that is not a control reply.
        """
        parts = ("replay", "control") if replay else ("control",)
        selector = service_key(self.root, vehicle, *parts)
        payload = json.dumps(dict(request)).encode()
        if replay:
            replies = list(self._get(selector, timeout or self.timeout, payload))
            errors = [r.error for r in replies if r.error is not None]
            if errors:
                msg = f"the replay of {vehicle}: {errors[0]}"
                raise QueryError(msg)
            if not replies:
                msg = f"no replay plays vehicle {vehicle!r} now (nothing answered {selector})"
                raise QueryError(msg)
        else:
            replies = self._replies(vehicle, selector, timeout, payload)
        return self._control_replies(vehicle, replies)

    def prune(
        self, vehicle: str, *, source: str = "", timeout: float | None = None
    ) -> list[ControlReply]:
        """Ask the vehicle's recorder to delete the sessions the shore acknowledged.

        Sent on ``<root>/V/@fleetlog/control/prune`` (access control grants it apart from the
        other commands); the vehicle's retention removes every acknowledged session except
        the one being recorded and those being fetched. The reply's extra fields say what
        was removed (``removed``, ``freed``, ``skipped``, ``kept``).

        Raises:
            QueryError: nothing answered (or access control refused), an error reply, or a
                reply that is not a control reply.
        """
        selector = service_key(self.root, vehicle, CONTROL, PRUNE)
        payload = json.dumps({"cmd": PRUNE, "source": source}).encode()
        replies = self._replies(vehicle, selector, timeout or max(self.timeout, 120.0), payload)
        return self._control_replies(vehicle, replies)

    @staticmethod
    def _control_replies(vehicle: str, replies: list[ReplyItem]) -> list[ControlReply]:
        out: list[ControlReply] = []
        for reply in replies:
            try:
                out.append(ControlReply.from_json(reply.payload, reply.replier))
            except FormatError as err:
                msg = f"vehicle {vehicle}: {err}"
                raise QueryError(msg) from None
        return out

    # -- recorder status

    def status(self, vehicle: str) -> list[VehicleStatus]:
        """Return the status of the vehicle's recorder (of each, if two answer).

        Raises:
            QueryError: no recorder answered (a vehicle served by ``fleetlog serve`` only
                has none), an error reply, or a reply that is not a status.
        """
        replies = self._replies(vehicle, service_key(self.root, vehicle, STATUS))
        out: list[VehicleStatus] = []
        for reply in replies:
            try:
                out.append(VehicleStatus.from_json(reply.payload, reply.replier))
            except FormatError as err:
                msg = f"vehicle {vehicle}: {err}"
                raise QueryError(msg) from None
        return out

    def status_all(self) -> dict[str, list[VehicleStatus]]:
        """Ask every recorder for its status at once: ``{vehicle: [status, ...]}``.

        Replies that are errors or unreadable are left out.

        Raises:
            TransportError: the query failed.
        """
        out: dict[str, list[VehicleStatus]] = {}
        for reply in self._get(fleet_service_selector(self.root, STATUS), self.timeout):
            if reply.error is not None:
                continue
            try:
                vehicle, _ = parse_service_key(self.root, reply.key)
                found = VehicleStatus.from_json(reply.payload, reply.replier)
            except FormatError:
                continue
            out.setdefault(vehicle, []).append(found)
        return out

    # -- sessions

    def latest_answers(self, vehicle: str) -> list[LatestInfo]:
        """Return a vehicle's latest session from every process that serves it (usually one).

        Raises:
            QueryError: no answer or an error reply.
        """
        payloads = self._samples(vehicle, service_key(self.root, vehicle, LATEST))
        answers: dict[str | None, LatestInfo] = {}
        for payload in payloads:
            try:
                info = LatestInfo.from_json(payload)
            except FormatError as err:
                msg = f"vehicle {vehicle}: {err}"
                raise QueryError(msg) from None
            answers.setdefault(info.server, info)
        return list(answers.values())

    def latest(self, vehicle: str, *, server: str | None = None) -> LatestInfo:
        """Return a vehicle's latest session (from the process ``server``, if given).

        Raises:
            ConflictError: two processes answer and ``server`` names neither.
            QueryError: no answer or an error reply.
        """
        answers = self.latest_answers(vehicle)
        if server is not None:
            answers = [a for a in answers if a.server == server]
            if not answers:
                msg = f"vehicle {vehicle}: no process {server} answers"
                raise QueryError(msg)
        if len(answers) > 1:
            raise ConflictError(vehicle, (a.server for a in answers))
        return answers[0]

    def latest_all(self) -> dict[str, list[LatestInfo]]:
        """Ask every vehicle for its latest session at once: ``{vehicle: [info, ...]}``.

        Each vehicle's list holds one answer per process that serves it (two after a
        partition healed between two recorders of it). Vehicles whose reply is an error or
        unreadable are left out.

        Raises:
            TransportError: the query failed.
        """
        selector = fleet_service_selector(self.root, LATEST)
        out: dict[str, dict[str | None, LatestInfo]] = {}
        for reply in self._get(selector, self.timeout):
            if reply.error is not None:
                continue
            try:
                vehicle, _ = parse_service_key(self.root, reply.key)
                info = LatestInfo.from_json(reply.payload)
            except FormatError:
                continue
            out.setdefault(vehicle, {}).setdefault(info.server, info)
        return {v: list(found.values()) for v, found in out.items()}

    def sessions(
        self,
        vehicle: str,
        *,
        brief: bool = False,
        timeout: float | None = None,
        server: str | None = None,
    ) -> list[SessionInfo]:
        """Return a vehicle's sessions, oldest first (from the process ``server``, if given).

        Raises:
            ConflictError: two processes answered and ``server`` named neither.
            QueryError: no answer, an error reply, or replies that are not a session list.
        """
        found = self.sessions_by_server(vehicle, brief=brief, timeout=timeout, server=server)
        if len(found) > 1:
            raise ConflictError(vehicle, found)
        return next(iter(found.values()))

    def sessions_by_server(
        self,
        vehicle: str,
        *,
        brief: bool = False,
        timeout: float | None = None,
        server: str | None = None,
    ) -> dict[str | None, list[SessionInfo]]:
        """Return each answering process's sessions of a vehicle: ``{zid: [session, ...]}``.

        Raises:
            QueryError: no answer, an error reply, or replies that are not a session list.
        """
        return self._sessions(vehicle, SessionsRequest(None, brief), timeout, server)

    def session(
        self, vehicle: str, name: str, *, brief: bool = True, server: str | None = None
    ) -> SessionInfo:
        """Return one session of a vehicle (from the process ``server``, if given).

        Raises:
            ConflictError: two processes hold the session and ``server`` named neither.
            QueryError: no such session, no answer, or an error reply.
        """
        by_server = self._sessions(vehicle, SessionsRequest(name, brief), None, server)
        if len(by_server) > 1:
            raise ConflictError(vehicle, by_server)
        found = next(iter(by_server.values()))
        if len(found) != 1:
            msg = f"vehicle {vehicle}: expected one session {name!r}, got {len(found)}"
            raise QueryError(msg)
        return found[0]

    def _sessions(
        self, vehicle: str, request: SessionsRequest, timeout: float | None, server: str | None
    ) -> dict[str | None, list[SessionInfo]]:
        selector = service_key(self.root, vehicle, SESSIONS)
        params = with_server(request.parameters(), server)
        if params:
            selector += "?" + params
        payloads = self._samples(vehicle, selector, timeout or max(self.timeout, 60.0))
        try:
            return sessions_by_server(payloads)
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
        server: str | None = None,
    ) -> PendingRange:
        """Send a range request without waiting; call ``result()`` on what it returns.

        Raises:
            FormatError: a name is not a single path component.
            TransportError: the query could not be sent.
        """
        request = FileRequest(offset, length, sha256)
        params = with_server(request.parameters(), server)
        selector = file_key(self.root, vehicle, session, name) + "?" + params
        handler = self._get(selector, timeout or self.timeout)  # at "bulk" priority
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
        server: str | None = None,
    ) -> tuple[bytes, FileMeta]:
        """Read a byte range of a file of a vehicle's session.

        Raises:
            QueryError: no answer, or an error reply (no such file, a path outside the log
                root, a range past the end...).
        """
        pending = self.request_range(
            vehicle, session, name, offset, length, sha256=sha256, server=server
        )
        return pending.result()

    def grep(
        self,
        vehicle: str,
        session: str,
        request: GrepRequest | None = None,
        *,
        server: str | None = None,
    ) -> GrepStream:
        """Start a remote grep over a session's alog; iterate the result for its records.

        Raises:
            FormatError: the session name is not a single path component.
            TransportError: the query could not be sent.
        """
        req = request or GrepRequest()
        params = with_server(req.parameters(), server)
        selector = grep_key(self.root, vehicle, session) + "?" + params
        return GrepStream(self, vehicle, selector, self._get(selector, self.grep_timeout))
