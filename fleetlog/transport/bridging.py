"""The Zenoh side of the MOOS bridge: exact publishing, a remote-only subscriber, link events.

* :class:`ExactPublisher` publishes a MOOS message with its value's bytes exactly as they came
  from the MOOSDB (a MOOS string is bytes, not necessarily UTF-8) and its own time, source,
  aux source and community (docs/wire.md).
* :class:`RemoteSubscriber` receives a vehicle's variables published by *other* Zenoh
  sessions only (``Locality.REMOTE``), so the bridge never receives its own publications, and
  turns each sample into a MOOS notification. A thread waits on the FIFO channel (without the
  GIL) and hands over batches: no polling.
* :class:`LinkWatch` follows the session's transports (routers and peers) through Zenoh's
  transport events, so losing the router is noticed when it happens.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable
from typing import Any

import zenoh

from fleetlog.errors import FormatError, TransportError
from fleetlog.moos.patterns import chunk_to_name
from fleetlog.moos.protocol import DataType, Message
from fleetlog.transport.bus import zenoh_time
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.message import (
    ENCODINGS,
    Kind,
    attachment_fields,
    classify_payload,
    encode_attachment,
    encode_value,
    kind_of_encoding,
)

__all__ = ["ExactPublisher", "LinkWatch", "RemoteSubscriber", "sample_to_message"]

_new_message = Message.__new__
_KIND_OF_TYPE = {DataType.DOUBLE: Kind.DOUBLE, DataType.STRING: Kind.STRING}
_DOUBLE_ENCODING = zenoh.Encoding(ENCODINGS[Kind.DOUBLE])
_STRING_ENCODING = zenoh.Encoding(ENCODINGS[Kind.STRING])
_BINARY_ENCODING = zenoh.Encoding(ENCODINGS[Kind.BINARY])


class ExactPublisher(MoosPublisher):
    """Publishes MOOS messages as they came from the MOOSDB (BLOCK, reliable)."""

    def __init__(self, session: zenoh.Session, root: str, vehicle: str, source: str) -> None:
        super().__init__(session, root, vehicle, source)
        #: (name, data type) -> its declared publisher: one lookup per message
        self._by_name: dict[tuple[str, str], Any] = {}

    def put_message(self, message: Message) -> None:
        """Publish one notification: payload, encoding and attachment from its fields.

        Raises:
            TransportError: Zenoh refused the put.
        """
        dtype = message.data_type
        pub = self._by_name.get((message.key, dtype))
        if pub is None:
            pub = self._declare(message.key, dtype)
        if dtype == "D":
            value = message.double
            payload = repr(value).encode("ascii") if value == value else encode_value(value)[1]
        else:
            payload = message.string
        attachment = encode_attachment(message.time, message.source, message.aux, message.community)
        try:
            pub.put(payload, attachment=attachment)
        except zenoh.ZError as err:
            msg = f"could not publish {message.key!r}: {err}"
            raise TransportError(msg) from err

    def _declare(self, name: str, dtype: str) -> Any:
        kind = Kind.DOUBLE if dtype == "D" else _KIND_OF_TYPE.get(dtype, Kind.BINARY)
        pub = self._publisher(self._key(self.vehicle, name), kind)
        if len(self._by_name) >= 4096:
            self._by_name.clear()
        self._by_name[(name, dtype)] = pub
        return pub

    def close(self) -> None:
        """Undeclare the publishers (the session stays open)."""
        self._by_name.clear()
        super().close()


def sample_to_message(
    sample: zenoh.Sample, prefix: str, names: dict[str, str | None], now: float, source: str
) -> tuple[Message | None, bool]:
    """Turn a sample of a vehicle's variable into a MOOS notification.

    Args:
        sample: the sample.
        prefix: the vehicle's variable key prefix (``fleet/V/var/``).
        names: a cache of key → MOOS name (None for keys that name none).
        now: the time to give a sample that carries none.
        source: the source to give a sample that carries none (a plain Zenoh publisher).

    Returns:
        ``(message, garbled)``: message is None when the key names no variable; garbled is
        True when the attachment was unreadable or the payload did not fit its encoding (the
        value is then posted as what it is).
    """
    key = str(sample.key_expr)
    name = names.get(key, "")
    if name == "":
        name = None
        if key.startswith(prefix):
            chunk = key[len(prefix) :]
            if chunk and "/" not in chunk:
                with contextlib.suppress(FormatError):
                    name = chunk_to_name(chunk) or None
        if len(names) > 65536:
            names.clear()
        names[key] = name
    if name is None:
        return None, True
    payload = sample.payload.to_bytes()
    encoding = sample.encoding
    garbled = False
    dtype: str
    double = -1.0
    string = b""
    if encoding == _DOUBLE_ENCODING:
        try:
            double = float(payload)
            dtype = DataType.DOUBLE
        except ValueError:
            garbled = True
            dtype, double, string = _classified(payload)
    elif encoding == _STRING_ENCODING:
        dtype, string = DataType.STRING, payload
    elif encoding == _BINARY_ENCODING:
        dtype, string = DataType.BINARY, payload
    else:
        declared = kind_of_encoding(str(encoding))
        if declared is Kind.STRING:
            dtype, string = DataType.STRING, payload
        elif declared is Kind.BINARY:
            dtype, string = DataType.BINARY, payload
        else:
            dtype, double, string = _classified(payload)
    when: float | None = None
    src = aux = community = ""
    attachment = sample.attachment
    if attachment is not None:
        try:
            when, src, aux, community, _ = attachment_fields(attachment.to_bytes())
        except FormatError:
            garbled = True
    if when is None or not math.isfinite(when):
        when = zenoh_time(sample) or now
    message = _new_message(
        Message, "N", dtype, name, when, double, string, src or source, aux, community, -1.0, -1
    )
    return message, garbled


def _classified(payload: bytes) -> tuple[str, float, bytes]:
    kind, value = classify_payload(payload)
    if kind is Kind.DOUBLE:
        assert isinstance(value, float)
        return DataType.DOUBLE, value, b""
    if kind is Kind.STRING:
        return DataType.STRING, -1.0, payload
    return DataType.BINARY, -1.0, payload


class RemoteSubscriber:
    """Receives samples from other sessions only, in a thread, handing over batches.

    Args:
        session: the Zenoh session.
        key_expr: what to subscribe to.
        on_samples: called in the receiving thread with each batch of samples (the first
            sample waits; what else is queued comes along). It may block to push back.
    """

    def __init__(
        self,
        session: zenoh.Session,
        key_expr: str,
        on_samples: Callable[[list[zenoh.Sample]], None],
        capacity: int = 65536,
    ) -> None:
        with translate_zerror(f"subscription to {key_expr!r}"):
            self._sub = session.declare_subscriber(
                key_expr,
                zenoh.handlers.FifoChannel(capacity),
                allowed_origin=zenoh.Locality.REMOTE,
            )
        self._on_samples = on_samples
        #: samples lost to an unexpected error while handing them over, and the last one
        self.errors = 0
        self.last_error = ""
        self._thread = threading.Thread(target=self._run, name="fleetlog-bridge-rx", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        # Waiting on the handler (not the subscriber) lets undeclare() end the wait.
        handler: Any = self._sub.handler
        on_samples = self._on_samples
        while True:
            try:
                first = handler.recv()
            except zenoh.ZError:
                return  # undeclared: the channel is closed and empty
            batch = [first]
            try:
                while len(batch) < 4096:
                    more = handler.try_recv()
                    if more is None:
                        break
                    batch.append(more)
            except zenoh.ZError:
                pass
            try:
                on_samples(batch)
            except Exception as err:  # the receiving thread must outlive any one batch
                self.errors += len(batch)
                self.last_error = f"{type(err).__name__}: {err}"

    def close(self, timeout: float = 5.0) -> None:
        """Undeclare the subscriber and wait for the thread to hand over what it holds."""
        with contextlib.suppress(zenoh.ZError):
            self._sub.undeclare()
        self._thread.join(timeout)


class LinkWatch:
    """Counts the session's open transports (routers and peers) from Zenoh's events.

    Args:
        session: the Zenoh session.
        on_change: called (in a Zenoh thread) with the number of open transports after each
            transport opens or closes.
    """

    def __init__(self, session: zenoh.Session, on_change: Callable[[int], None]) -> None:
        self._open: set[str] = set()
        self._lock = threading.Lock()
        self._on_change = on_change
        with translate_zerror("transport events"):
            self._listener = session.info.declare_transport_events_listener(
                self._event, history=True
            )

    @property
    def count(self) -> int:
        """Transports open now."""
        with self._lock:
            return len(self._open)

    def _event(self, event: Any) -> None:
        zid = str(event.transport.zid)
        with self._lock:
            if event.kind == zenoh.SampleKind.PUT:
                self._open.add(zid)
            else:
                self._open.discard(zid)
            count = len(self._open)
        self._on_change(count)

    def close(self) -> None:
        """Stop listening."""
        with contextlib.suppress(zenoh.ZError):
            self._listener.undeclare()
