"""The shore side: which vehicles are up, what they hold, and fetching it.

:class:`~fleetlog.shore.client.FleetClient` asks vehicles (``latest``, ``sessions``, file
ranges, remote grep); :func:`~fleetlog.shore.fetch.fetch_session` downloads a session,
resumable and verified; :class:`~fleetlog.shore.collect.Collector` mirrors every vehicle's
sessions into a shore archive (``fleetlog collect``). The vehicle side it talks to is
:mod:`fleetlog.query`; the protocol is :mod:`fleetlog.wire.query` (docs/wire.md, "Query
services").
"""

from fleetlog.shore.client import FleetClient
from fleetlog.shore.collect import Collector
from fleetlog.shore.fetch import fetch_session

__all__ = ["Collector", "FleetClient", "fetch_session"]
