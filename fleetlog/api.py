r"""The Python API for vehicle apps: publish MOOS variables that fleetlog records.

Example::

    from fleetlog.api import Vehicle

    with Vehicle("alpha", source="iGPS") as v:
        v.publish("NAV_X", 12.5)
        v.publish("DEPLOY", "true")
        v.publish("CAMERA_FRAME", b"\x00\x01")
        v.confirm()          # wait until the vehicle's recorder has received them

Publishing uses Zenoh's BLOCK congestion control: a publisher slows down rather than lose
samples a recorder is waiting for. ``drop=True`` selects DROP for control loops that must never
stall; losses are then possible, and the recorder counts them (sample-miss detection,
docs/wire.md).
"""

from __future__ import annotations

from types import TracebackType

from fleetlog.errors import QueryError
from fleetlog.transport.bus import wait_for_subscriber
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.queries import ZenohSession
from fleetlog.transport.services import get_replies, live_vehicles
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import DEFAULT_ROOT, check_root, service_key, var_key

__all__ = ["Vehicle", "find_recorder"]


def find_recorder(session: ZenohSession, root: str = DEFAULT_ROOT, timeout: float = 2.0) -> str:
    """Return the vehicle of the one recorder this session can reach.

    Raises:
        QueryError: no recorder, or several (the message names them).
    """
    vehicles = sorted(live_vehicles(session, root, ("recorder",), timeout=timeout))
    if not vehicles:
        msg = "no fleetlog recorder is reachable; name the vehicle with --vehicle"
        raise QueryError(msg)
    if len(vehicles) > 1:
        msg = f"several recorders are reachable ({', '.join(vehicles)}); choose one with --vehicle"
        raise QueryError(msg)
    return vehicles[0]


class Vehicle:
    """A connection that publishes one vehicle's MOOS variables.

    Args:
        vehicle: the vehicle (MOOS community); None finds the one reachable recorder.
        source: the source process name the recorder logs.
        options: how to open Zenoh (an embedded peer by default).
        root: the key root.
        drop: DROP congestion control instead of BLOCK; the samples are numbered so that the
            recorder counts what is dropped.
        session: an already open session to use (it is then not closed here).
    """

    def __init__(
        self,
        vehicle: str | None = None,
        *,
        source: str = "fleetlog",
        options: SessionOptions | None = None,
        root: str = DEFAULT_ROOT,
        drop: bool = False,
        session: ZenohSession | None = None,
    ) -> None:
        self.root = check_root(root)
        self._own = session is None
        self.session = open_session(options or SessionOptions()) if session is None else session
        try:
            self.vehicle = vehicle if vehicle is not None else find_recorder(self.session, root)
        except BaseException:
            self.close()
            raise
        self._publisher = MoosPublisher(self.session, root, self.vehicle, source, drop=drop)
        self.published = 0

    def publish(
        self,
        name: str,
        value: float | str | bytes,
        *,
        source: str | None = None,
        aux: str = "",
        time: float | None = None,
    ) -> None:
        """Publish one variable (float: double, str: string, bytes: binary)."""
        self._publisher.publish(name, value, source=source, aux=aux, time=time)
        self.published += 1

    def wait_for_subscriber(self, name: str, timeout: float = 3.0) -> bool:
        """Wait until something subscribes to ``name``'s key; False on timeout.

        A put made before the subscription is known goes nowhere, so short-lived publishers
        (``fleetlog poke``) wait first.
        """
        return wait_for_subscriber(self.session, var_key(self.root, self.vehicle, name), timeout)

    def confirm(self, timeout: float = 5.0) -> bool:
        """Wait until the vehicle's recorder has received everything published so far.

        A query travels behind the samples on the same link, so the recorder's answer
        proves they arrived. Returns False when no recorder answered (samples may still
        have reached other subscribers).
        """
        try:
            replies = get_replies(
                self.session, service_key(self.root, self.vehicle, "status"), timeout=timeout
            )
        except QueryError:
            return False
        return bool(replies)

    def close(self) -> None:
        """Undeclare and close (the session only if this object opened it)."""
        pub = getattr(self, "_publisher", None)
        if pub is not None:
            pub.close()
        if self._own:
            self.session.close()

    def __enter__(self) -> Vehicle:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
