"""fleetlog's one error hierarchy.

Every error fleetlog raises descends from :class:`FleetlogError`, so the CLI can turn any of
them into one clear sentence on stderr and a non-zero exit::

    FleetlogError
    ├── FormatError          pure MOOS/wire parsing: names the file, line and field
    │   └── MissionError     a .moos mission file that cannot be used
    ├── StorageError         reading or writing session files (disk full, read-only, corrupt)
    ├── TransportError       Zenoh: bad options, session failures (zenoh.ZError is translated)
    ├── RecorderError        the recorder cannot start or continue
    ├── QueryError           a remote request failed or was refused
    ├── ReplayError          a replay cannot proceed
    └── UsageError           a command was given arguments it cannot use
"""

from __future__ import annotations

__all__ = [
    "FleetlogError",
    "FormatError",
    "MissionError",
    "QueryError",
    "RecorderError",
    "ReplayError",
    "StorageError",
    "TransportError",
    "UsageError",
]


class FleetlogError(Exception):
    """Root of every error fleetlog raises on purpose."""


class FormatError(FleetlogError):
    """Text or bytes that do not follow a MOOS or fleetlog format.

    Args:
        reason: what is wrong, as a sentence fragment.
        path: the file (or other source name) the text came from, if known.
        lineno: the 1-based line number, if known.
    """

    def __init__(self, reason: str, path: str | None = None, lineno: int | None = None) -> None:
        self.reason = reason
        self.path = path
        self.lineno = lineno
        where = ""
        if path is not None and lineno is not None:
            where = f"{path}:{lineno}: "
        elif path is not None:
            where = f"{path}: "
        elif lineno is not None:
            where = f"line {lineno}: "
        super().__init__(f"{where}{reason}")


class MissionError(FormatError):
    """A MOOS mission file that cannot be parsed or configures something impossible."""


class StorageError(FleetlogError):
    """A session file could not be read or written."""


class TransportError(FleetlogError):
    """Zenoh could not be configured, opened or used."""


class RecorderError(FleetlogError):
    """The recorder cannot start or continue."""


class QueryError(FleetlogError):
    """A request to a vehicle's services failed, was refused or got no answer."""


class ReplayError(FleetlogError):
    """A replay cannot proceed."""


class UsageError(FleetlogError):
    """A command was given arguments it cannot use."""
