"""The Zenoh side of a replay: publishing, PLAYBACK_CHOKE, the control queryable, the status.

Keys, for each vehicle ``V`` the replay publishes to (after ``--prefix``):

* ``<root>/V/var/VAR``: the replayed variables (docs/wire.md), BLOCK congestion control;
* ``<root>/V/var/PLAYBACK_CHOKE``: subscribed; a client's heartbeat (a double, its clock's
  time). Samples that are themselves replays (their attachment carries an original time) are
  ignored, so replaying a log that holds PLAYBACK_CHOKE never chokes the replay itself;
* ``<root>/V/@fleetlog/replay/control``: a queryable speaking fleetlog's control schema
  (docs/wire.md, "Control"): a JSON request in the payload (at most 64 KiB) or selector
  parameters (``?cmd=pause``; ``;`` or ``&`` between them), read by
  :func:`fleetlog.replayer.control.parse_request`. It answers ``{"ok", "cmd", "did", "why"}``
  with the status after the command, or an error reply for a malformed request;
* ``<root>/V/@fleetlog/replay/status``: the status as JSON, published a few times a second
  and answered to queries;
* ``<root>/V/@fleetlog/replay``: a liveliness token while the replay runs, so
  ``fleetlog replay-ctl`` finds running replays as the shore finds vehicles.

Every vehicle's control key steers the same replay: the vehicles share one clock.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from fleetlog.errors import FormatError, QueryError
from fleetlog.transport.bus import matching
from fleetlog.transport.publisher import MoosPublisher, Sender
from fleetlog.transport.services import get_replies
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.keys import service_key, var_key
from fleetlog.wire.message import (
    Kind,
    MoosMessage,
    decode_attachment,
    decode_value,
    kind_of_encoding,
)

__all__ = ["CHOKE_VARIABLE", "MAX_CONTROL", "ReplayLink"]

#: The variable a client posts its heartbeat to (uPlayBack's PLAYBACK_CHOKE).
CHOKE_VARIABLE = "PLAYBACK_CHOKE"
_JSON = zenoh.Encoding("application/json")

#: ``handler(payload, parameters) -> reply JSON``; raises a FleetlogError for a malformed
#: request (answered with an error reply).
ControlHandler = Callable[[bytes | None, str], bytes]
#: the largest control request read (docs/wire.md, "Control")
MAX_CONTROL = 64 << 10


class ReplayLink:
    """Publishes a replay's messages and serves its control and status over one session.

    Args:
        session: an open Zenoh session (not closed here).
        root: the key root.
        vehicles: the vehicles the replay publishes to.
    """

    def __init__(self, session: zenoh.Session, root: str, vehicles: Sequence[str]) -> None:
        self.session = session
        self.root = root
        self.vehicles = tuple(dict.fromkeys(vehicles))
        self._data = MoosPublisher(session, root, self.vehicles[0] if self.vehicles else "")
        self._declared: list[Any] = []
        self._status_pubs: list[zenoh.Publisher] = []

    # -- data

    # The puts of MoosPublisher (docs/wire.md), with prepare(): the player declares a
    # variable's publisher while it waits, not when the entry is due.

    def prepare(self, vehicle: str, name: str, kind: Kind) -> None:
        """Declare the publisher of a variable before its first publication.

        Raises:
            TransportError: the declaration failed.
        """
        self._data.prepare(name, kind, vehicle)

    def publish(self, vehicle: str, message: MoosMessage) -> None:
        """Publish one message under ``vehicle`` (BLOCK, reliable).

        Its community defaults to the vehicle, as a live process's would.

        Raises:
            TransportError: Zenoh refused the put.
        """
        self._data.send(message, vehicle)

    def sender(
        self, vehicle: str, name: str, kind: Kind, source: str, aux: str, community: str
    ) -> Sender:
        """Return a sender of one variable of ``vehicle`` with this origin (BLOCK, reliable).

        Raises:
            TransportError: the publisher's declaration failed.
        """
        return self._data.sender(name, kind, source, aux, community, vehicle)

    def wait_for_subscribers(self, timeout: float) -> list[str]:
        """Wait until every vehicle's variables have a subscriber; return those without one.

        A put made before a subscription is known goes nowhere, so the replay waits (up to
        ``timeout``) until, for each vehicle, something subscribes to its variables.
        """
        pubs = {
            vehicle: self.session.declare_publisher(var_key(self.root, vehicle, CHOKE_VARIABLE))
            for vehicle in self.vehicles
        }
        try:
            deadline = time.monotonic() + timeout
            while True:
                missing = [v for v, pub in pubs.items() if not matching(pub)]
                if not missing or time.monotonic() >= deadline:
                    return missing
                time.sleep(0.01)
        finally:
            for pub in pubs.values():
                pub.undeclare()

    def confirm_delivery(self, timeout: float) -> list[str]:
        """Make sure what was published reached each vehicle's recorder; return the others.

        A query to the vehicle's recorder status travels behind the samples on the same
        link, so its answer proves the recorder has them. Vehicles without a recorder get
        a short grace period instead, so plain subscribers are not cut off by the close.
        """
        unconfirmed: list[str] = []
        for vehicle in self.vehicles:
            try:
                replies = get_replies(
                    self.session, service_key(self.root, vehicle, "status"), timeout=timeout
                )
            except QueryError:
                replies = []
            if not replies:
                unconfirmed.append(vehicle)
        if unconfirmed:
            time.sleep(0.3)
        return unconfirmed

    # -- PLAYBACK_CHOKE

    def on_choke(self, callback: Callable[[float], None]) -> None:
        """Call ``callback(client_time)`` for each PLAYBACK_CHOKE heartbeat a client posts.

        Raises:
            TransportError: the subscription failed.
        """

        def receive(sample: zenoh.Sample) -> None:
            kind = kind_of_encoding(str(sample.encoding))
            found, value, garbled = decode_value(sample.payload.to_bytes(), kind)
            if garbled or found is not Kind.DOUBLE or not isinstance(value, float):
                return
            attachment = sample.attachment
            if attachment is not None:
                try:
                    if decode_attachment(attachment.to_bytes()).original_time is not None:
                        return  # a replayed heartbeat, maybe our own
                except FormatError:
                    pass
            callback(value)

        for vehicle in self.vehicles:
            key = var_key(self.root, vehicle, CHOKE_VARIABLE)
            with translate_zerror(f"subscription to {key!r}"):
                self._declared.append(self.session.declare_subscriber(key, receive))

    # -- control and status

    def serve(self, control: ControlHandler, status: Callable[[], dict[str, Any]]) -> None:
        """Declare the control and status queryables of every vehicle.

        Raises:
            TransportError: a declaration failed.
        """

        def answer(query: zenoh.Query, document: Callable[[], bytes]) -> None:
            try:
                body = document()
            except Exception as err:  # malformed, or a bug: either way the query gets an answer
                with contextlib.suppress(zenoh.ZError):
                    query.reply_err(str(err))
                return
            with contextlib.suppress(zenoh.ZError):
                query.reply(query.key_expr, body, encoding=_JSON)

        def on_control(query: zenoh.Query) -> None:
            payload = query.payload
            if payload is not None and len(payload) > MAX_CONTROL:
                data: bytes | None = bytes(MAX_CONTROL + 1)  # refused unread, by its size
            else:
                data = None if payload is None else payload.to_bytes()
            parameters = str(query.parameters)
            answer(query, lambda: control(data, parameters))

        def on_status(query: zenoh.Query) -> None:
            answer(query, lambda: json.dumps(status()).encode())

        for vehicle in self.vehicles:
            for name, handler in (("control", on_control), ("status", on_status)):
                key = service_key(self.root, vehicle, "replay", name)
                with translate_zerror(f"queryable on {key!r}"):
                    self._declared.append(self.session.declare_queryable(key, handler))
            key = service_key(self.root, vehicle, "replay", "status")
            with translate_zerror(f"publisher on {key!r}"):
                self._status_pubs.append(self.session.declare_publisher(key, encoding=_JSON))
            key = service_key(self.root, vehicle, "replay")
            with translate_zerror(f"liveliness token {key!r}"):
                self._declared.append(self.session.liveliness().declare_token(key))

    def publish_status(self, document: dict[str, Any]) -> None:
        """Publish the status on every vehicle's status key (dropped if nobody keeps up)."""
        text = json.dumps(document)
        for pub in self._status_pubs:
            with contextlib.suppress(zenoh.ZError):
                pub.put(text)

    def close(self) -> None:
        """Undeclare everything (the session stays open)."""
        for pub in self._status_pubs:
            pub.undeclare()
        self._status_pubs.clear()
        for entity in self._declared:
            entity.undeclare()
        self._declared.clear()
        self._data.close()
