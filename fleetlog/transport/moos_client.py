"""An asynchronous MOOS client on asyncio: one TCP connection to a MOOSDB, event-driven.

It speaks the protocol of :mod:`fleetlog.moos.protocol` as an *asynchronous* V10 client
(every C++ MOOS app since V10 is one): the DB pushes mail as soon as it has any, and the client
sends what is queued as soon as the event loop runs, so nothing waits for a comms tick. A
timing message every second keeps the connection alive (the DB drops a client silent for more
than 5 s). Nothing polls: the socket's readiness drives the reading, and posts are written
when the loop next runs.

:meth:`MoosClient.maintain` keeps the connection up: it connects, re-registers every
subscription after each (re)connection, and retries while the DB is down, restarting or
unreachable, reporting each change of state to a callback.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleetlog.errors import FormatError, TransportError
from fleetlog.moos.protocol import DEFAULT_MAX_PACKET, Message, MsgType, PacketReader, encode_packet
from fleetlog.moos.requests import (
    HANDSHAKE,
    Welcome,
    handshake_message,
    parse_welcome,
    register,
    timing_message,
    unregister,
    wildcard_register,
)

__all__ = ["MoosClient", "MoosRefusedError", "Subscription"]

#: seconds between timing messages (the C++ async client's TIMING_MESSAGE_PERIOD)
TIMING_PERIOD = 1.0
#: the most bytes put into one packet when a backlog is written
MAX_WRITE_PACKET = 1 << 20
#: asyncio's write buffer above which writers are asked to wait
WRITE_HIGH_WATER = 4 << 20


class MoosRefusedError(TransportError):
    """The MOOSDB refused the handshake (a client of that name is already connected)."""


@dataclass(frozen=True, slots=True)
class Subscription:
    """A registration the client renews after every reconnection.

    Attributes:
        var: the variable, or the variable pattern of a wildcard registration.
        app: the app pattern of a wildcard registration; None for a plain one.
        interval: the least seconds between two deliveries (0: every message).
    """

    var: str
    app: str | None = None
    interval: float = 0.0


class _Protocol(asyncio.Protocol):
    def __init__(self, client: MoosClient, max_packet: int) -> None:
        self.client = client
        self.reader = PacketReader(max_packet)
        self.skipped = 0
        self.transport: asyncio.Transport | None = None
        loop = asyncio.get_running_loop()
        self.welcome: asyncio.Future[list[Message]] = loop.create_future()
        self.lost: asyncio.Future[str] = loop.create_future()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None:
            # MOOS turns Nagle off too: small posts must not wait for an ACK.
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        transport.set_write_buffer_limits(high=WRITE_HIGH_WATER)

    def data_received(self, data: bytes) -> None:
        try:
            packets = self.reader.feed(data)
        except FormatError as err:
            self._close(f"the MOOSDB sent a malformed packet ({err})")
            return
        if self.reader.oversized != self.skipped:
            self.client._oversized(self.reader.oversized - self.skipped)
            self.skipped = self.reader.oversized
        if not packets:
            return
        if not self.welcome.done():
            self.welcome.set_result(packets[0])
            packets = packets[1:]
        for messages in packets:
            self.client._packet(messages)

    def _close(self, reason: str) -> None:
        if not self.lost.done():
            self.lost.set_result(reason)
        if self.transport is not None:
            self.transport.abort()

    def connection_lost(self, exc: Exception | None) -> None:
        reason = "the MOOSDB closed the connection" if exc is None else f"connection lost: {exc}"
        if not self.lost.done():
            self.lost.set_result(reason)
        if not self.welcome.done():
            self.welcome.set_exception(TransportError(reason))
        self.client._writable.set()

    def pause_writing(self) -> None:
        self.client._writable.clear()

    def resume_writing(self) -> None:
        self.client._writable.set()


class MoosClient:
    """An asynchronous MOOS client.

    Args:
        name: the client's name in the community (unique per MOOSDB).
        host: the MOOSDB's host.
        port: the MOOSDB's port.
        on_mail: called with the messages of each packet the DB pushes (notifications and
            server replies; the timing reply at a packet's head is taken off), in the event
            loop, in arrival order.
        max_packet: the largest packet accepted; larger ones are skipped and counted.
        clock: the wall clock (MOOS time of the client's own messages).
        connect_timeout: seconds a connection attempt and its handshake may take.
    """

    def __init__(
        self,
        name: str,
        host: str,
        port: int,
        *,
        on_mail: Callable[[list[Message]], None],
        max_packet: int = DEFAULT_MAX_PACKET,
        clock: Callable[[], float] = time.time,
        connect_timeout: float = 5.0,
    ) -> None:
        self.name = name
        self.host = host
        self.port = port
        self._on_mail = on_mail
        self._max_packet = max_packet
        self._clock = clock
        self.connect_timeout = connect_timeout
        self._protocol: _Protocol | None = None
        self._out: list[Message] = []
        self._flush_pending = False
        self._subscriptions: dict[tuple[str, str | None], Subscription] = {}
        self._beat: asyncio.TimerHandle | None = None
        self._stopping = False
        #: set while the socket accepts more writes (cleared when its buffer is full)
        self._writable = threading.Event()
        self._writable.set()
        self.welcome: Welcome | None = None
        #: the DB's time in its last timing reply, and our clock when it came
        self.db_time: tuple[float, float] | None = None
        #: the DB's requested pause after each write (``m_dfVal2`` of its timing replies)
        self.pacing = 0.0
        #: packets skipped for being larger than ``max_packet``
        self.oversized_packets = 0
        self.connections = 0

    # ---------------------------------------------------------------------------------------
    # State

    @property
    def connected(self) -> bool:
        """True while a handshaken connection is open."""
        proto = self._protocol
        return proto is not None and self.welcome is not None and not proto.lost.done()

    @property
    def writable(self) -> threading.Event:
        """Set while the socket accepts more data; producers in other threads wait on it."""
        return self._writable

    @property
    def subscriptions(self) -> list[Subscription]:
        """The registrations renewed after every reconnection."""
        return list(self._subscriptions.values())

    def buffered(self) -> int:
        """Bytes written but not yet taken by the socket."""
        proto = self._protocol
        if proto is None or proto.transport is None:
            return 0
        return proto.transport.get_write_buffer_size()

    # ---------------------------------------------------------------------------------------
    # Connecting

    async def connect(self) -> Welcome:
        """Connect and handshake once.

        Raises:
            MoosRefusedError: the DB refused the name.
            TransportError: the DB is not reachable, did not answer, or closed.
        """
        loop = asyncio.get_running_loop()
        proto = _Protocol(self, self._max_packet)
        where = f"{self.host}:{self.port}"
        try:
            async with asyncio.timeout(self.connect_timeout):
                await loop.create_connection(lambda: proto, self.host, self.port)
                assert proto.transport is not None
                hello = handshake_message(self.name, self._clock())
                proto.transport.write(HANDSHAKE + encode_packet([hello]))
                reply = await proto.welcome
        except TimeoutError:
            proto._close("handshake timed out")
            msg = f"the MOOSDB at {where} did not answer within {self.connect_timeout:g} s"
            raise TransportError(msg) from None
        except OSError as err:
            msg = f"cannot connect to the MOOSDB at {where}: {err.strerror or err}"
            raise TransportError(msg) from None
        try:
            welcome = parse_welcome(reply)
        except FormatError as err:
            proto._close(str(err))
            raise MoosRefusedError(str(err)) from None
        self._protocol = proto
        self.welcome = welcome
        self.connections += 1
        self._out.clear()
        self._send_subscriptions()
        self._beat_now()
        return welcome

    async def wait_closed(self) -> str:
        """Wait until the current connection ends; return why."""
        proto = self._protocol
        if proto is None:
            return "not connected"
        return await proto.lost

    async def maintain(
        self,
        on_up: Callable[[Welcome], None],
        on_down: Callable[[str], None],
        on_retry: Callable[[TransportError], None],
        retry: float = 1.0,
    ) -> None:
        """Keep connected until :meth:`close`: connect, wait, reconnect.

        Args:
            on_up: called after each successful handshake (subscriptions already renewed).
            on_down: called when an established connection ends, with the reason.
            on_retry: called when an attempt fails, with the error (the caller decides
                what to report: it repeats every ``retry`` seconds while the DB is away).
            retry: seconds between attempts.
        """
        while not self._stopping:
            try:
                welcome = await self.connect()
            except TransportError as err:
                on_retry(err)
                await asyncio.sleep(retry)
                continue
            on_up(welcome)
            reason = await self.wait_closed()
            self._drop_connection()
            if self._stopping:
                return
            on_down(reason)
            await asyncio.sleep(min(retry, 0.2))

    def _drop_connection(self) -> None:
        if self._beat is not None:
            self._beat.cancel()
            self._beat = None
        self.welcome = None
        self._out.clear()
        self._writable.set()

    def close(self) -> None:
        """Close the connection (after writing what is queued) and stop :meth:`maintain`."""
        self._stopping = True
        self._flush()
        proto = self._protocol
        if proto is not None and proto.transport is not None:
            proto.transport.close()
            if not proto.lost.done():
                proto.lost.set_result("closed")
        self._drop_connection()

    # ---------------------------------------------------------------------------------------
    # Subscriptions

    def subscribe(self, var: str, interval: float = 0.0) -> None:
        """Register for a variable, now and after every reconnection."""
        sub = Subscription(var, None, interval)
        self._subscriptions[(var, None)] = sub
        if self.connected:
            self.send([register(self.name, var, interval, self._clock())])

    def subscribe_wildcard(
        self, var_pattern: str, app_pattern: str = "*", interval: float = 0.0
    ) -> None:
        """Register for every variable matching ``var_pattern`` (MOOS globs).

        Raises:
            ValueError: a pattern holds ``,`` or ``=``.
        """
        message = wildcard_register(self.name, var_pattern, app_pattern, interval, self._clock())
        self._subscriptions[(var_pattern, app_pattern)] = Subscription(
            var_pattern, app_pattern, interval
        )
        if self.connected:
            self.send([message])

    def unsubscribe(self, var: str) -> None:
        """Unregister a plain subscription."""
        if self._subscriptions.pop((var, None), None) is not None and self.connected:
            self.send([unregister(self.name, var, self._clock())])

    def _send_subscriptions(self) -> None:
        now = self._clock()
        messages: list[Message] = []
        for sub in self._subscriptions.values():
            if sub.app is None:
                messages.append(register(self.name, sub.var, sub.interval, now))
            else:
                messages.append(wildcard_register(self.name, sub.var, sub.app, sub.interval, now))
        if messages:
            self.send(messages)

    # ---------------------------------------------------------------------------------------
    # Sending

    def send(self, messages: Sequence[Message]) -> bool:
        """Queue messages for the DB; they leave when the event loop next runs.

        Returns:
            False (and nothing is queued) when there is no connection.
        """
        if not self.connected:
            return False
        self._out.extend(messages)
        if not self._flush_pending:
            self._flush_pending = True
            asyncio.get_running_loop().call_soon(self._flush)
        return True

    def _flush(self) -> None:
        self._flush_pending = False
        out = self._out
        proto = self._protocol
        if not out or proto is None or proto.transport is None or proto.lost.done():
            out.clear()
            return
        self._out = []
        write = proto.transport.write
        start = 0
        size = 0
        for i, message in enumerate(out):
            size += 60 + len(message.key) + len(message.string) + len(message.source)
            if size >= MAX_WRITE_PACKET:
                write(encode_packet(out[start : i + 1]))
                start = i + 1
                size = 0
        if start < len(out):
            write(encode_packet(out[start:]))

    def _beat_now(self) -> None:
        proto = self._protocol
        if proto is None or proto.transport is None or proto.lost.done():
            return
        # The timing message leads its packet, as the DB expects; queued posts follow.
        queued = self._out
        self._out = []
        proto.transport.write(encode_packet([timing_message(self._clock())]))
        if queued:
            self._out = queued
            self._flush()
        loop = asyncio.get_running_loop()
        self._beat = loop.call_later(TIMING_PERIOD, self._beat_now)

    # ---------------------------------------------------------------------------------------
    # Receiving (called by the protocol)

    def _packet(self, messages: list[Message]) -> None:
        if messages and messages[0].msg_type in (MsgType.TIMING, MsgType.NULL):
            head = messages[0]
            self.db_time = (head.double, self._clock())
            if head.msg_type == MsgType.TIMING and head.double2 > 0:
                self.pacing = head.double2
            messages = messages[1:]
        if messages:
            self._on_mail(messages)

    def _oversized(self, packets: int) -> None:
        self.oversized_packets += packets
