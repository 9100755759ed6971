"""The fleet view of a shore archive: per vehicle, what is on shore, what only on the vehicle.

Read from the archive alone (the collector's records and the files), so ``fleetlog collect
--status`` answers whether or not the collector runs, without touching the network. What is
*in flight* is what the running collector last wrote (every 2 s); with no collector running
nothing is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import FormatError, StorageError
from fleetlog.storage.archive import (
    COMPLETE,
    CUT,
    VehicleRecord,
    collector_running,
    load_record,
    session_bytes,
    vehicle_dirs,
)

__all__ = ["ArchiveHoldings", "SessionHolding", "VehicleHoldings", "holdings"]


@dataclass(frozen=True)
class SessionHolding:
    """One session: its state on shore, and what the vehicle said of it last.

    Attributes:
        name: the session.
        state: ``complete``, ``cut``, ``partial`` or ``missing``.
        vehicle_state: its metadata's state on the vehicle.
        on_vehicle: the vehicle still held it when last listed.
        here: bytes on shore (complete files and ``.part`` files).
        vehicle_bytes: bytes the vehicle listed.
        acked: when the vehicle acknowledged it.
        pruned: when the vehicle deleted it at the collector's request.
        completed: when it was complete on shore.
    """

    name: str
    state: str
    vehicle_state: str | None
    on_vehicle: bool
    here: int
    vehicle_bytes: int
    acked: float | None
    pruned: float | None
    completed: float | None

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` object."""
        return {
            "name": self.name,
            "state": self.state,
            "vehicle_state": self.vehicle_state,
            "on_vehicle": self.on_vehicle,
            "bytes_here": self.here,
            "bytes_on_vehicle": self.vehicle_bytes,
            "acked": self.acked,
            "pruned": self.pruned,
            "completed": self.completed,
        }


@dataclass
class VehicleHoldings:
    """One vehicle's line of the fleet view."""

    vehicle: str
    up: bool
    seen: float | None
    error: str | None
    received: int
    sessions: list[SessionHolding] = field(default_factory=list)
    in_flight: list[dict[str, Any]] = field(default_factory=list)

    @property
    def on_shore(self) -> list[SessionHolding]:
        """Sessions complete or cut on shore."""
        return [s for s in self.sessions if s.state in (COMPLETE, CUT)]

    @property
    def only_on_vehicle(self) -> list[SessionHolding]:
        """Sessions the vehicle holds that are not all here yet."""
        return [s for s in self.sessions if s.on_vehicle and s.state not in (COMPLETE, CUT)]

    def missing_bytes(self) -> int:
        """Bytes the vehicle holds that are not on shore yet."""
        return sum(max(0, s.vehicle_bytes - s.here) for s in self.only_on_vehicle)

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` object."""
        shore = self.on_shore
        return {
            "vehicle": self.vehicle,
            "up": self.up,
            "seen": self.seen,
            "error": self.error,
            "received": self.received,
            "on_shore": {
                "sessions": len(shore),
                "complete": sum(s.state == COMPLETE for s in shore),
                "cut": sum(s.state == CUT for s in shore),
                "bytes": sum(s.here for s in shore),
            },
            "only_on_vehicle": {
                "sessions": len(self.only_on_vehicle),
                "bytes": self.missing_bytes(),
            },
            "in_flight": self.in_flight,
            "acknowledged": sum(s.acked is not None for s in self.sessions),
            "pruned": sum(s.pruned is not None for s in self.sessions),
            "sessions": [s.as_json() for s in self.sessions],
        }


@dataclass
class ArchiveHoldings:
    """The fleet view of an archive.

    Attributes:
        archive: the archive directory.
        running: a collector runs on it now.
        vehicles: one entry per vehicle directory.
        unreadable: directories whose record could not be read, and why.
    """

    archive: Path
    running: bool
    vehicles: list[VehicleHoldings] = field(default_factory=list)
    unreadable: dict[str, str] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` document."""
        return {
            "archive": str(self.archive),
            "collector_running": self.running,
            "vehicles": [v.as_json() for v in self.vehicles],
            "unreadable": self.unreadable,
        }


def _vehicle(directory: Path, record: VehicleRecord, running: bool) -> VehicleHoldings:
    found = VehicleHoldings(
        record.vehicle,
        record.up and running,
        record.seen,
        record.error,
        record.received,
        in_flight=list(record.in_flight) if running else [],
    )
    for name, entry in sorted(record.sessions.items()):
        done, partial = session_bytes(directory / name)
        found.sessions.append(
            SessionHolding(
                name,
                entry.state,
                entry.vehicle_state,
                entry.on_vehicle,
                done + partial,
                entry.remote_size,
                entry.acked,
                entry.pruned,
                entry.completed,
            )
        )
    return found


def holdings(archive: Path) -> ArchiveHoldings:
    """Read the fleet view of an archive.

    Raises:
        StorageError: the archive cannot be listed.
    """
    if not archive.is_dir():
        msg = f"{archive} is not an archive directory"
        raise StorageError(msg)
    running = collector_running(archive)
    view = ArchiveHoldings(archive, running)
    for directory in vehicle_dirs(archive):
        try:
            record = load_record(directory)
        except (StorageError, FormatError) as err:
            view.unreadable[directory.name] = str(err)
            continue
        if record is not None:
            view.vehicles.append(_vehicle(directory, record, running))
    return view
