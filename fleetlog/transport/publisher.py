"""Publishing MOOS messages over a Zenoh session (docs/wire.md): apps, poke, bridge, replay.

Everything fleetlog publishes that someone may log uses BLOCK congestion control and reliable
delivery: the default DROP lost most samples at full speed on a 2-core machine. A publisher
that must never stall uses DROP with zenoh-ext's sample-miss detection, and the recorder counts
what it lost (:class:`~fleetlog.transport.bus.MissCounter`).

A replay publishes millions of entries whose variable and origin repeat: a :class:`Sender`
holds what repeats (the key, the attachment's strings) so that each entry costs its payload,
two time fields and the put.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

import zenoh
import zenoh.ext

from fleetlog.errors import TransportError
from fleetlog.transport.bus import MISS_HEARTBEAT
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.keys import var_key
from fleetlog.wire.message import (
    ENCODINGS,
    TIME_FIELD,
    Kind,
    MoosMessage,
    attachment_tail,
    encode_attachment,
    encode_value,
)

__all__ = ["MoosPublisher", "Sender"]

_ENCODING_OBJECTS: dict[Kind, zenoh.Encoding] = {k: zenoh.Encoding(v) for k, v in ENCODINGS.items()}
_pack_time = TIME_FIELD.pack


class MoosPublisher:
    """Publishes MOOS messages of one vehicle (BLOCK congestion control, reliable).

    Args:
        session: an open Zenoh session.
        root: the key root (``fleet``).
        vehicle: the vehicle (MOOS community) the variables belong to.
        source: the default source process name.
        drop: use DROP congestion control, for control loops that must never stall. The
            publisher then numbers its samples (zenoh-ext's sample-miss detection, with a
            heartbeat every :data:`MISS_HEARTBEAT` seconds), so that a recorder counts what
            was dropped (docs/wire.md).
    """

    def __init__(
        self,
        session: zenoh.Session,
        root: str,
        vehicle: str,
        source: str = "",
        *,
        drop: bool = False,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._session = session
        self._root = root
        self.vehicle = vehicle
        self.source = source
        self._clock = clock
        self._drop = drop
        self._congestion = zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK
        self._publishers: dict[tuple[str, Kind], zenoh.Publisher | zenoh.ext.AdvancedPublisher] = {}
        self._keys: dict[tuple[str, str], str] = {}

    def _publisher(self, key: str, kind: Kind) -> zenoh.Publisher | zenoh.ext.AdvancedPublisher:
        # A declared publisher per key is much cheaper per put than session.put.
        pub = self._publishers.get((key, kind))
        if pub is None:
            if len(self._publishers) >= 4096:
                self.close()
            with translate_zerror(f"publisher on {key!r}"):
                if self._drop:
                    # Numbered samples and a heartbeat: a recorder counts what DROP loses.
                    # The heartbeat is periodic (DROP itself), never BLOCK.
                    pub = zenoh.ext.declare_advanced_publisher(
                        self._session,
                        key,
                        encoding=_ENCODING_OBJECTS[kind],
                        congestion_control=self._congestion,
                        reliability=zenoh.Reliability.RELIABLE,
                        sample_miss_detection=zenoh.ext.MissDetectionConfig(
                            heartbeat=MISS_HEARTBEAT, sporadic_heartbeat=None
                        ),
                    )
                else:
                    pub = self._session.declare_publisher(
                        key,
                        encoding=_ENCODING_OBJECTS[kind],
                        congestion_control=self._congestion,
                        reliability=zenoh.Reliability.RELIABLE,
                    )
            self._publishers[(key, kind)] = pub
        return pub

    def _key(self, vehicle: str, name: str) -> str:
        key = self._keys.get((vehicle, name))
        if key is None:
            key = var_key(self._root, vehicle, name)
            if len(self._keys) > 65536:
                self._keys.clear()
            self._keys[(vehicle, name)] = key
        return key

    def prepare(self, name: str, kind: Kind, vehicle: str | None = None) -> None:
        """Declare a variable's publisher before its first publication.

        A declaration costs about a millisecond; a replay prepares while it waits for an
        entry's time rather than when the entry is due.

        Raises:
            TransportError: the declaration failed.
        """
        self._publisher(self._key(self.vehicle if vehicle is None else vehicle, name), kind)

    def close(self) -> None:
        """Undeclare the publishers (the session stays open)."""
        publishers = list(self._publishers.values())
        self._publishers.clear()
        for pub in publishers:
            with contextlib.suppress(zenoh.ZError):
                pub.undeclare()  # type: ignore[no-untyped-call]  # zenoh.ext's stub

    def publish(
        self,
        name: str,
        value: float | str | bytes,
        *,
        time: float | None = None,
        source: str | None = None,
        aux: str = "",
        community: str | None = None,
        original_time: float | None = None,
        vehicle: str | None = None,
    ) -> None:
        """Publish one MOOS message.

        Args:
            name: the MOOS variable.
            value: float (double), str (string) or bytes (binary).
            time: the message time (epoch seconds); now by default.
            source: the source process; the publisher's default otherwise.
            aux: the aux source.
            community: the originating community; the vehicle by default.
            original_time: for replayed samples, the recorded absolute time.
            vehicle: publish under another vehicle than the publisher's (replay of a fleet).

        Raises:
            TransportError: Zenoh refused the put.
        """
        veh = self.vehicle if vehicle is None else vehicle
        self._put(
            name,
            value,
            self._clock() if time is None else time,
            self.source if source is None else source,
            aux,
            veh if community is None else community,
            original_time,
            veh,
        )

    def _put(
        self,
        name: str,
        value: float | str | bytes,
        time: float,
        source: str,
        aux: str,
        community: str,
        original_time: float | None,
        vehicle: str,
    ) -> None:
        """Put one message, every field given (:meth:`publish` and :meth:`send`; no keywords)."""
        kind, payload = encode_value(value)
        key = self._key(vehicle, name)
        attachment = encode_attachment(time, source, aux, community, original_time)
        pub = self._publishers.get((key, kind))
        if pub is None:
            pub = self._publisher(key, kind)
        try:
            pub.put(payload, attachment=attachment)
        except zenoh.ZError as err:
            msg = f"could not publish {name!r} on {key!r}: {err}"
            raise TransportError(msg) from err

    def send(self, message: MoosMessage, vehicle: str | None = None) -> None:
        """Publish a :class:`MoosMessage` as it is (its own time, source and community)."""
        # The replayer's path, once per sample: straight to the put, no keyword arguments.
        veh = self.vehicle if vehicle is None else vehicle
        self._put(
            message.name,
            message.value,
            message.time,
            message.source,
            message.aux,
            message.community or veh,
            message.original_time,
            veh,
        )

    def sender(
        self, name: str, kind: Kind, source: str, aux: str, community: str, vehicle: str
    ) -> Sender:
        """Return a :class:`Sender` of one variable of ``vehicle``, with this origin.

        Raises:
            TransportError: the publisher's declaration failed.
        """
        key = self._key(vehicle, name)
        self._publisher(key, kind)
        return Sender(self, key, kind, attachment_tail(source, aux, community))


class Sender:
    """Publishes one variable of one vehicle with a fixed origin (a replay's per-entry path).

    It holds the key and the attachment's strings; the publisher itself is looked up at each
    send in its :class:`MoosPublisher` (which may undeclare its publishers to bound them), and
    declared again if it was.
    """

    __slots__ = ("_ident", "_owner", "_publishers", "_tail")

    def __init__(self, owner: MoosPublisher, key: str, kind: Kind, tail: bytes) -> None:
        self._owner = owner
        self._publishers = owner._publishers
        self._ident = (key, kind)
        self._tail = tail

    def send(self, payload: bytes, time: float, original_time: float) -> None:
        """Publish a payload with its time and original (recorded) time.

        Raises:
            TransportError: Zenoh refused the put, or the publisher could not be declared.
        """
        pub = self._publishers.get(self._ident)
        if pub is None:
            pub = self._owner._publisher(*self._ident)
        try:
            pub.put(payload, attachment=_pack_time(time) + self._tail + _pack_time(original_time))
        except zenoh.ZError as err:
            msg = f"could not publish on {self._ident[0]!r}: {err}"
            raise TransportError(msg) from err
