"""The vehicle side of the query services: a vehicle's log root served over Zenoh.

:class:`~fleetlog.query.server.LogServer` serves a log root (``latest``, ``sessions``, files
by byte range, remote grep). The shore side, which asks the vehicles, is :mod:`fleetlog.shore`.
The protocol is :mod:`fleetlog.wire.query` (docs/wire.md, "Query services").
"""

from fleetlog.query.server import LogServer

__all__ = ["LogServer"]
