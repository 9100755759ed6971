"""What an operator installs: a fleet's certificates, router and client configurations.

``FleetKit`` makes and keeps a fleet directory (``fleetlog deploy init/renew/revoke``);
``configs`` writes the security profile's Zenoh configurations from the access table in
:mod:`fleetlog.wire.access`; ``pki`` issues certificates with the ``cryptography`` library.
"""

from fleetlog.deploy.fleet import Fleet, Machine
from fleetlog.deploy.kit import FleetKit, Renewal

__all__ = ["Fleet", "FleetKit", "Machine", "Renewal"]
