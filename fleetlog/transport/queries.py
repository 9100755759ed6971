"""Queryables and queries as fleetlog's services use them, with ZError translated.

The query services (:mod:`fleetlog.query`) see plain strings and bytes: an
:class:`IncomingQuery` to answer, :class:`ReplyItem` objects to read. Zenoh stays here.

**Queryables deliver into a FIFO channel drained by a thread of their own**
(:class:`ServiceQueryable`), not into a Python callback: a callback runs on Zenoh's network
thread and needs the GIL, so while a worker holds the GIL (a grep) every query would stall the
link that also carries the recorder's samples. The channel's ``recv`` waits without the GIL.
The handler is read through ``queryable.handler``: a thread blocked in ``queryable.recv()``
holds a borrow that makes ``undeclare()`` fail ("Already borrowed"), while one blocked on the
handler is released by ``undeclare()`` with a ZError ("channel is empty and closed").

**Queries** ask for every reply (``ConsolidationMode.NONE``): a grep or a session listing
answers with several replies on one key, which the default consolidation would merge away.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TypeAlias

import zenoh

from fleetlog.errors import TransportError
from fleetlog.transport.session import translate_zerror

__all__ = [
    "PRIORITIES",
    "IncomingQuery",
    "LivelinessToken",
    "PendingQuery",
    "ReplyItem",
    "ServiceQueryable",
    "ZenohSession",
    "declare_token",
    "session_zid",
    "start_query",
]

#: the session type, for modules that must name it without importing zenoh
ZenohSession: TypeAlias = zenoh.Session

_log = logging.getLogger("fleetlog.transport.queries")
_ENCODINGS: dict[str, zenoh.Encoding] = {}


def _encoding(name: str) -> zenoh.Encoding:
    found = _ENCODINGS.get(name)
    if found is None:
        found = _ENCODINGS[name] = zenoh.Encoding(name)
    return found


class IncomingQuery:
    """A query received by a :class:`ServiceQueryable`.

    Attributes:
        key: the query's key expression (it may hold wildcards).
        parameters: the selector's parameters, as sent.

    The payload, which only some services read, is read with :meth:`payload`.
    """

    __slots__ = ("_finished", "_query", "key", "parameters")

    def __init__(self, query: zenoh.Query) -> None:
        self._query = query
        self._finished = False
        self.key = str(query.key_expr)
        self.parameters = str(query.parameters)

    def payload(self, limit: int) -> bytes | None:
        """Return the query's payload (None without one).

        One over ``limit`` bytes comes back as ``limit + 1`` zero bytes, so the caller can
        refuse it without copying it whole.
        """
        body = self._query.payload
        if body is None:
            return None
        if len(body) > limit:
            return bytes(limit + 1)
        return body.to_bytes()

    @property
    def selector(self) -> str:
        """The key and parameters, for logs."""
        return f"{self.key}?{self.parameters}" if self.parameters else self.key

    def reply(
        self, key: str, payload: bytes, *, encoding: str, attachment: bytes | None = None
    ) -> None:
        """Send one reply on ``key`` (a concrete key that the query's key intersects).

        Raises:
            TransportError: the reply could not be sent (the querier is gone).
        """
        with translate_zerror(f"reply on {key!r}"):
            self._query.reply(key, payload, encoding=_encoding(encoding), attachment=attachment)

    def reply_err(self, message: str) -> None:
        """Send an error reply; a querier that is gone is not an error."""
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._query.reply_err(message)

    def finish(self) -> None:
        """Tell the querier no more replies come (without it, it waits for its timeout).

        The querier's ``get`` ends only then, so call it as soon as the last reply is sent;
        calling it again does nothing.
        """
        if self._finished:
            return
        self._finished = True
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._query.drop()


class ServiceQueryable:
    """A queryable whose queries reach ``on_query`` from a dispatcher thread of its own.

    ``on_query`` must return quickly (hand the query to a worker) and finish every query it
    takes, one way or another. The thread is zenoh-python's own for an indirect callback:
    it waits in the channel's ``recv`` without a timeout, so an idle queryable costs no CPU
    (a thread of ours in ``Handler.recv`` woke ten times a second to check for signals).
    Queries wait in a channel of 256 before Zenoh does.

    Args:
        session: the session.
        key: the key expression served.
        on_query: receives each query.

    Raises:
        TransportError: Zenoh refused the declaration.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        on_query: Callable[[IncomingQuery], None],
    ) -> None:
        self.key = key
        self._on_query = on_query
        #: set when the dispatcher thread has ended (Zenoh drops the callback after its last call)
        self._ended = threading.Event()
        handler = zenoh.handlers.Callback(self._dispatch, self._ended.set, indirect=True)
        with translate_zerror(f"queryable {key!r}"):
            self._queryable = session.declare_queryable(key, handler)

    def _dispatch(self, query: zenoh.Query) -> None:
        incoming = IncomingQuery(query)
        try:
            self._on_query(incoming)
        except Exception:  # the dispatcher must outlive any one query
            _log.exception("handing over query %s failed", incoming.selector)
            incoming.reply_err("internal error: the query could not be handled")
            incoming.finish()

    def undeclare(self, timeout: float = 2.0) -> None:
        """Stop receiving queries; wait until the last one was handed over."""
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._queryable.undeclare()
        self._ended.wait(timeout)


class LivelinessToken:
    """A declared liveliness token ("this service is up")."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        with translate_zerror(f"liveliness token {key!r}"):
            self._token = session.liveliness().declare_token(key)

    def undeclare(self) -> None:
        """Withdraw the token."""
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._token.undeclare()


def declare_token(session: zenoh.Session, key: str) -> LivelinessToken:
    """Declare a liveliness token.

    Raises:
        TransportError: Zenoh refused the declaration.
    """
    return LivelinessToken(session, key)


@dataclass(frozen=True, slots=True)
class ReplyItem:
    """One reply to a query: a sample (``error`` None) or an error reply.

    Attributes:
        key: the reply's key (empty for an error reply).
        payload: the sample's payload (empty for an error reply).
        attachment: the sample's attachment, if any.
        error: the error reply's text.
        replier: the Zenoh id of the process that replied, if Zenoh says.
    """

    key: str
    payload: bytes
    attachment: bytes | None = None
    error: str | None = None
    replier: str | None = None


#: Zenoh priorities by what a query is for. A reply travels at its query's priority (Zenoh
#: 1.10 matches the reply's QoS to the query's), so on a shared radio link commands and
#: telemetry overtake the file ranges and greps of fetch and collect, which go at Zenoh's
#: lowest priority (still on the bulk link of deploy's two: priorities 5-7).
PRIORITIES: dict[str, zenoh.Priority] = {
    "bulk": zenoh.Priority.BACKGROUND,
    "normal": zenoh.Priority.DATA,
    "command": zenoh.Priority.INTERACTIVE_HIGH,
}


class PendingQuery:
    """A query in flight; iterate it for its replies (it ends when the query does)."""

    def __init__(
        self,
        session: zenoh.Session,
        selector: str,
        timeout: float,
        payload: bytes | None = None,
        priority: str = "normal",
    ) -> None:
        self.selector = selector
        with translate_zerror(f"query {selector!r}"):
            self._handler = session.get(
                selector,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=timeout,
                payload=payload,
                priority=PRIORITIES[priority],
            )

    def __iter__(self) -> Iterator[ReplyItem]:
        try:
            for reply in self._handler:
                sample = reply.ok
                replier = reply.replier_id
                who = None if replier is None else str(replier.zid)
                if sample is not None:
                    attachment = sample.attachment
                    yield ReplyItem(
                        str(sample.key_expr),
                        sample.payload.to_bytes(),
                        None if attachment is None else attachment.to_bytes(),
                        None,
                        who,
                    )
                elif reply.err is not None:
                    yield ReplyItem("", b"", None, reply.err.payload.to_string(), who)
        except zenoh.ZError as err:
            msg = f"query {self.selector!r} failed: {err}"
            raise TransportError(msg) from err


def start_query(
    session: zenoh.Session,
    selector: str,
    *,
    timeout: float,
    payload: bytes | None = None,
    priority: str = "normal",
) -> PendingQuery:
    """Send a query (with ``payload``, e.g. a control request) without waiting for replies.

    ``priority``: ``bulk`` (file ranges, grep: Zenoh's background priority), ``normal``, or
    ``command`` (control, status).

    Raises:
        TransportError: the query could not be sent.
    """
    return PendingQuery(session, selector, timeout, payload, priority)


def session_zid(session: zenoh.Session) -> str:
    """Return the session's Zenoh id, as text (the recorder id of the session metadata)."""
    with translate_zerror("session id"):
        return str(session.zid())
