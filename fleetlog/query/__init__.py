"""The query services: a vehicle's log root served over Zenoh, and the shore client.

:class:`~fleetlog.query.server.LogServer` serves a log root (``latest``, ``sessions``, files
by byte range, remote grep); :class:`~fleetlog.query.client.FleetClient` asks vehicles;
:func:`~fleetlog.query.fetch.fetch_session` downloads a session, resumable and verified.
The protocol is :mod:`fleetlog.wire.query` (docs/wire.md, "Query services").
"""

from fleetlog.query.client import FleetClient
from fleetlog.query.fetch import fetch_session
from fleetlog.query.server import LogServer

__all__ = ["FleetClient", "LogServer", "fetch_session"]
