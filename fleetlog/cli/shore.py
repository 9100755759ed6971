"""What the shore commands share: opening the fleet client from the Zenoh options."""

from __future__ import annotations

from pathlib import Path

from fleetlog.cli.options import checked_root, session_options
from fleetlog.shore.client import FleetClient

__all__ = ["open_client"]


def open_client(
    root: str,
    mode: str | None,
    connect: list[str] | None,
    listen: list[str] | None,
    config: Path | None,
    no_multicast_scouting: bool,
    *,
    timeout: float = 10.0,
    grep_timeout: float = 300.0,
) -> FleetClient:
    """Open a :class:`FleetClient` with the shared command-line options.

    Raises:
        UsageError: an option is unusable.
        TransportError: the Zenoh session cannot be opened.
    """
    key_root = checked_root(root)
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    return FleetClient.open(zopts, root=key_root, timeout=timeout, grep_timeout=grep_timeout)
