"""A Zenoh router on zenoh-python: the role of ``zenohd``, for sites without it.

The router is Zenoh's own (routing, TLS, access control, QoS are Zenoh's code, configured by
the same JSON5 file zenohd reads); this module opens it, reports the links that come and go,
and closes it. ``fleetlog router`` runs it as a service.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from fleetlog.errors import TransportError
from fleetlog.transport.session import SessionOptions, translate_zerror

__all__ = ["Router", "RouterInfo"]


@dataclass(frozen=True, slots=True)
class RouterInfo:
    """What a started router says about itself."""

    zid: str
    listen: tuple[str, ...]
    connect: tuple[str, ...]
    access_control: bool
    subjects: int


class Router:
    """A Zenoh session in router mode.

    Args:
        options: the configuration (``mode`` is forced to ``router``).
        on_event: receives one line per link that opens or closes (from a thread of ours).

    Raises:
        TransportError: the configuration is unusable or a listen endpoint cannot be bound.
    """

    def __init__(self, options: SessionOptions, on_event: Callable[[str], None]) -> None:
        conf = options.to_config()
        with translate_zerror("configuration"):
            conf.insert_json5("mode", '"router"')
        self.info = _describe(conf)
        with translate_zerror("router start"):
            self._session = zenoh.open(conf)
        self.info = dataclasses.replace(self.info, zid=str(self._session.info.zid()))
        self._events: queue.Queue[str | None] = queue.Queue()
        self._on_event = on_event
        # The listener's callback runs on a Zenoh thread: it only queues the line.
        with translate_zerror("transport events"):
            self._listener = self._session.info.declare_transport_events_listener(
                self._queue_event, history=True
            )
        self._thread = threading.Thread(target=self._report, name="fleetlog-router", daemon=True)
        self._thread.start()

    def _queue_event(self, event: zenoh.TransportEvent) -> None:
        transport = event.transport
        what = "connected" if event.kind == zenoh.SampleKind.PUT else "disconnected"
        self._events.put(f"{what}: {transport.whatami} {transport.zid}")

    def _report(self) -> None:
        while True:
            line = self._events.get()
            if line is None:
                return
            with contextlib.suppress(Exception):  # reporting must never stop the router
                self._on_event(line)

    def alive(self) -> bool:
        """Whether the router still answers (its runtime is not wedged)."""
        try:
            self._session.info.zid()
        except (zenoh.ZError, RuntimeError):
            return False
        return True

    def neighbours(self) -> tuple[int, int]:
        """The routers and the peers/clients connected now."""
        try:
            transports = self._session.info.transports()
        except (zenoh.ZError, RuntimeError):
            return 0, 0
        routers = sum(1 for t in transports if t.whatami == zenoh.WhatAmI.ROUTER)
        return routers, len(transports) - routers

    def close(self) -> None:
        """Close the router (its links drop; clients reconnect elsewhere or later)."""
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._listener.undeclare()
        self._events.put(None)
        self._thread.join(2.0)
        with contextlib.suppress(zenoh.ZError, RuntimeError):
            self._session.close()


def _describe(conf: zenoh.Config) -> RouterInfo:
    def get(key: str) -> object:
        try:
            return json.loads(conf.get_json(key))
        except (zenoh.ZError, ValueError):
            return None

    def endpoints(key: str) -> tuple[str, ...]:
        value = get(key)
        if isinstance(value, dict):
            value = value.get("router")
        return tuple(str(v) for v in value) if isinstance(value, list) else ()

    acl = get("access_control")
    enabled = isinstance(acl, dict) and acl.get("enabled") is True
    subjects = len(acl.get("subjects") or []) if isinstance(acl, dict) else 0
    listen = endpoints("listen/endpoints")
    if not listen:
        msg = "a router needs an endpoint to listen on (-l or listen/endpoints in the config)"
        raise TransportError(msg)
    return RouterInfo("", listen, endpoints("connect/endpoints"), enabled, subjects)
