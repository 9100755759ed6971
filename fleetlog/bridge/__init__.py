"""The MOOS bridge: a MOOSDB's community on Zenoh, and Zenoh's samples in the MOOSDB.

:class:`~fleetlog.bridge.service.BridgeService` runs it; :class:`~fleetlog.bridge.forward.Forwarder`
holds the rules (no loops, no duplicates, MOOS's type rule, counts).
"""

from fleetlog.bridge.forward import BridgeStats, Forwarder
from fleetlog.bridge.service import BridgeOptions, BridgeService

__all__ = ["BridgeOptions", "BridgeService", "BridgeStats", "Forwarder"]
