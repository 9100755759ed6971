"""What the fleet client's queries hand back: reply errors, a range in flight, a grep stream.

:class:`~fleetlog.shore.client.FleetClient` asks; this module reads the answers:
:func:`reply_error` turns a vehicle's error reply into a :class:`TransientQueryError` (busy,
closing: worth retrying) or a :class:`QueryError`, :class:`ConflictError` names two processes
answering for one vehicle, :class:`PendingRange` waits for one file range's reply, and
:class:`GrepStream` yields a remote grep's records as they arrive (:func:`record_entry` turns
one back into the entry a local read gives).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, QueryError
from fleetlog.moos.alog import BinaryRef, Entry, parse_binary_ref
from fleetlog.transport.queries import PendingQuery
from fleetlog.wire.query import (
    FileMeta,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    decode_grep_lines,
)

if TYPE_CHECKING:
    from fleetlog.shore.client import FleetClient

__all__ = [
    "ConflictError",
    "GrepStream",
    "PendingRange",
    "TransientQueryError",
    "record_entry",
    "reply_error",
]

#: error replies that say "not now" rather than "never": a client may retry them
_TRANSIENT_REPLIES = ("the log server is busy", "the log server is closing")


class TransientQueryError(QueryError):
    """Nobody answered, or the vehicle said it is busy or closing: worth retrying later."""


class ConflictError(QueryError):
    """Two processes answer for one vehicle where one answer is needed.

    Attributes:
        vehicle: the vehicle.
        servers: the Zenoh ids of the processes that answered.
    """

    def __init__(self, vehicle: str, servers: Iterable[str | None]) -> None:
        self.vehicle = vehicle
        self.servers = sorted(s or "?" for s in servers)
        super().__init__(
            f"{len(self.servers)} processes answer for vehicle {vehicle!r}"
            f" ({', '.join(self.servers)}): two recorders of one vehicle (a partition that"
            " healed?); name one with --server ZID"
        )


def reply_error(vehicle: str, text: str) -> QueryError:
    """The error a vehicle's error reply means: transient (busy, closing) or not."""
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
            raise reply_error(self.vehicle, error)
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
                raise reply_error(self.vehicle, reply.error)
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
