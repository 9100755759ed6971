"""A recorder's status, as the shore reads it (``<root>/V/@fleetlog/status``, docs/wire.md).

The reply comes from the network, so it is read defensively: every field is optional and
checked for its type, numbers must be finite, texts are cut to a bounded length, the whole
reply is at most 1 MiB, and of the ``commands`` ring (the outcomes of the recorder's last
commands, :class:`~fleetlog.wire.control.CommandRecord`) the last 64 readable entries are kept.
A field this version does not know is kept in :attr:`VehicleStatus.raw` for ``--json``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.control import CommandRecord
from fleetlog.wire.json_fields import parse_json

__all__ = ["COUNTERS", "VehicleStatus", "describe_command"]

#: the counters a recorder reports, in the order a table shows them
COUNTERS = (
    "received",
    "logged",
    "excluded",
    "ignored",
    "throttled",
    "skewed",
    "garbled",
    "lost",
    "missed",
    "write_errors",
    "refused_copies",
    "sessions",
)
#: at most this many commands are read from a status reply
MAX_COMMANDS = 64
#: texts from the vehicle are cut to this many characters
MAX_TEXT = 512
#: a status reply larger than this is refused unread
MAX_STATUS = 1 << 20


def _text(value: Any) -> str | None:
    if not isinstance(value, str):
        return None
    return value if len(value) <= MAX_TEXT else value[: MAX_TEXT - 1] + "…"


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _count(value: Any) -> int | None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        return None
    return value


def describe_command(record: CommandRecord) -> str:
    """One line: the command, and what was done or why it was refused."""
    what = record.text or record.cmd
    if record.ok:
        return f"{what}: {record.did or 'done'}"
    return f"{what}: refused: {record.why or 'no reason given'}"


def _commands(ring: Any) -> tuple[CommandRecord, ...]:
    """The ring's entries that can be read (a garbled one is left out), the last 64."""
    out: list[CommandRecord] = []
    for item in ring[-MAX_COMMANDS:] if isinstance(ring, list) else []:
        try:
            out.append(CommandRecord.from_json(item))
        except FormatError:
            continue
    return tuple(out)


@dataclass(frozen=True)
class VehicleStatus:
    """One recorder's status reply.

    Attributes:
        vehicle: the vehicle, as the recorder names it.
        server: the Zenoh id of the recorder that answered, if known.
        directory: the current session directory (as LOGGER_DIRECTORY), if one is open.
        session: the current session's name.
        counters: the counters (:data:`COUNTERS`, and any other whole-number field).
        last_error: the last error the recorder met, or empty.
        commands: the outcomes of its last commands, oldest first.
        disk_free: bytes free where it writes, if it says.
        disk_total: the size of that file system, if it says.
        clock: the clock's state, as the recorder reports it (``synchronized``, ...).
        paused: whether recording is paused, if it says.
        writing: whether a session is open and taking lines, if it says.
        problem: why it is not writing (``disk-full``, ...), if it says.
        raw: the whole reply, for ``--json``.
    """

    vehicle: str
    server: str | None = None
    directory: str | None = None
    session: str | None = None
    counters: Mapping[str, int] = field(default_factory=dict)
    last_error: str = ""
    commands: tuple[CommandRecord, ...] = ()
    disk_free: int | None = None
    disk_total: int | None = None
    clock: Mapping[str, Any] = field(default_factory=dict)
    paused: bool | None = None
    writing: bool | None = None
    problem: str | None = None
    raw: Mapping[str, Any] = field(default_factory=dict)

    @property
    def state(self) -> str:
        """``recording``, ``paused``, or ``NOT WRITING`` with the reason."""
        if self.problem or self.writing is False or (self.writing is None and not self.session):
            return f"NOT WRITING ({self.problem or 'no session open'})"
        return "paused" if self.paused else "recording"

    @property
    def losses(self) -> int:
        """Samples lost (the ``lost`` counter; ``missed`` ones of logged variables are in it)."""
        return self.counters.get("lost", 0)

    @property
    def clock_synchronized(self) -> bool | None:
        """Whether the vehicle's clock is synchronised, if the recorder says."""
        value = self.clock.get("synchronized")
        return value if isinstance(value, bool) else None

    @classmethod
    def from_json(cls, data: bytes, server: str | None = None) -> VehicleStatus:
        """Read a status reply.

        Raises:
            FormatError: not a JSON object, too large, or without a vehicle name.
        """
        if len(data) > MAX_STATUS:
            msg = f"the status reply is {len(data)} bytes long; at most {MAX_STATUS}"
            raise FormatError(msg)
        try:
            obj = parse_json(data)
        except (ValueError, RecursionError) as err:
            msg = f"the status reply is not JSON: {str(err)[:80]}"
            raise FormatError(msg) from None
        if not isinstance(obj, dict):
            msg = "the status reply is not a JSON object"
            raise FormatError(msg)
        vehicle = _text(obj.get("vehicle"))
        if not vehicle:
            msg = "the status reply names no vehicle"
            raise FormatError(msg)
        counters = {
            name: found
            for name, value in obj.items()
            if isinstance(name, str) and (found := _count(value)) is not None
        }
        commands = _commands(obj.get("commands"))
        disk = obj.get("disk")
        disk = disk if isinstance(disk, dict) else {}
        clock = obj.get("clock")
        paused = obj.get("paused")
        writing = obj.get("writing")
        directory = _text(obj.get("directory"))
        session = _text(obj.get("session"))
        if session is None and directory:
            session = directory.rstrip("/").rsplit("/", 1)[-1] or None  # as LOGGER_DIRECTORY
        return cls(
            vehicle=vehicle,
            server=server,
            directory=directory,
            session=session,
            counters=counters,
            last_error=_text(obj.get("last_error")) or "",
            commands=commands,
            disk_free=_count(disk.get("free")),
            disk_total=_count(disk.get("total")),
            clock=clock if isinstance(clock, dict) else {},
            paused=paused if isinstance(paused, bool) else None,
            writing=writing if isinstance(writing, bool) else None,
            problem=_text(obj.get("problem")) or None,
            raw=obj,
        )
