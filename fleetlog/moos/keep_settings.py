"""What the recorder keeps: the snapshot ring, and the disk's bounds (fleetlog's own settings).

Pure code. :func:`read_snapshot_settings` and :func:`read_disk_settings` read them from a
parsed pLogger block; :func:`parse_trigger` reads a ``SnapshotTrigger`` (shared with the
command line, so both take and refuse the same text; docs/compat.md, "Snapshot mode" and
"Disk guard and retention")::

    SnapshotSeconds = 30          // keep the last 30 s in memory; write only on SNAPSHOT
    SnapshotMemory  = 256MB       // ... and never more than this
    SnapshotAfter   = 10          // a snapshot records on for 10 s past its trigger
    SnapshotTrigger = ALARM == 1  // a SNAPSHOT when ALARM changes to 1 (repeatable)
    MinFreeDisk     = 2GB         // stop writing before the disk is full
    KeepSessions    = 20          // keep at most 20 sessions in the log root
    MaxLogSize      = 50GB        // keep at most this much in the log root
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, MissionError
from fleetlog.moos.settings import is_moos_numeric, key
from fleetlog.moos.units import parse_duration, parse_size

if TYPE_CHECKING:
    from fleetlog.moos.mission import Param, ProcessBlock

__all__ = [
    "DEFAULT_MIN_FREE_DISK",
    "DEFAULT_SNAPSHOT_MEMORY",
    "MAX_SNAPSHOT_SECONDS",
    "MAX_TRIGGERS",
    "MIN_SNAPSHOT_MEMORY",
    "DiskSettings",
    "SnapshotSettings",
    "Trigger",
    "parse_trigger",
    "read_disk_settings",
    "read_snapshot_settings",
    "with_disk_options",
    "with_snapshot_options",
]

#: the ring's memory bound unless ``SnapshotMemory`` says otherwise
DEFAULT_SNAPSHOT_MEMORY = 256 * 10**6
#: the smallest memory bound taken (a smaller ring holds a handful of samples)
MIN_SNAPSHOT_MEMORY = 10**5
#: the longest window and the longest "after" taken: a day (longer is a recording, not a
#: snapshot)
MAX_SNAPSHOT_SECONDS = 86400.0
#: trigger lines a block may hold
MAX_TRIGGERS = 16
#: ``MinFreeDisk`` unless the block says otherwise: off, as pLogger writes until the disk is
#: full (the recorder survives that, docs/reliability.md §1); a vehicle should set it
DEFAULT_MIN_FREE_DISK = 0
#: the most sessions ``KeepSessions`` may name (a typo guard)
_MAX_KEEP = 10**6
_MAX_TRIGGER_TEXT = 512
_OTHERS = tuple(key(name) for name in ("SnapshotMemory", "SnapshotAfter", "SnapshotTrigger"))


@dataclass(frozen=True, slots=True)
class Trigger:
    """``SnapshotTrigger = VAR == value``: a SNAPSHOT when ``VAR`` changes to ``value``.

    Attributes:
        var: the MOOS variable watched.
        value: the value it must change to: a number (a double sample equal to it) or a
            text (a string sample equal to it, blanks around it trimmed).
    """

    var: str
    value: float | str

    def matches(self, value: float | str | bytes) -> bool:
        """Return True when a sample's value is the trigger's value."""
        if isinstance(self.value, float):
            return isinstance(value, float) and value == self.value
        return isinstance(value, str) and value.strip() == self.value

    def text(self) -> str:
        """The trigger as written (``ALARM == 1``)."""
        value = self.value
        shown = f"{value:g}" if isinstance(value, float) else value
        return f"{self.var} == {shown}"


@dataclass(frozen=True, slots=True)
class SnapshotSettings:
    """Snapshot mode: nothing is written until a SNAPSHOT (docs/compat.md).

    Attributes:
        seconds: ``SnapshotSeconds``: the window kept in memory (every sample of the last
            this many seconds, plus each variable's latest older value).
        memory: ``SnapshotMemory``: the most bytes the ring may hold; past it the oldest
            samples are evicted (counted).
        after: ``SnapshotAfter``: how long a snapshot records on past its trigger.
        triggers: ``SnapshotTrigger`` lines.
    """

    seconds: float
    memory: int = DEFAULT_SNAPSHOT_MEMORY
    after: float = 0.0
    triggers: tuple[Trigger, ...] = ()


@dataclass(frozen=True, slots=True)
class DiskSettings:
    """The disk guard and retention (docs/compat.md, "Disk guard and retention").

    Attributes:
        min_free: ``MinFreeDisk``: writing stops while the log root's file system has less
            free space than this (0: only a full disk stops it).
        keep_sessions: ``KeepSessions``: the most sessions kept in the log root (None: no
            bound).
        max_log_size: ``MaxLogSize``: the most bytes the log root's sessions may hold
            (None: no bound).
    """

    min_free: int = DEFAULT_MIN_FREE_DISK
    keep_sessions: int | None = None
    max_log_size: int | None = None

    @property
    def retention(self) -> bool:
        """True when a bound may remove sessions (``KeepSessions`` or ``MaxLogSize``)."""
        return self.keep_sessions is not None or self.max_log_size is not None


def parse_trigger(text: str) -> Trigger:
    """Read ``VAR == value``.

    A value that reads as a number (as MOOS reads one) matches double samples equal to it;
    any other value matches string samples equal to it.

    Raises:
        FormatError: not ``VAR == value``, an empty or malformed name, or an empty value.
    """
    if len(text) > _MAX_TRIGGER_TEXT:
        msg = f"a trigger is {len(text)} characters long: at most {_MAX_TRIGGER_TEXT}"
        raise FormatError(msg)
    var, sep, value = text.partition("==")
    var, value = var.strip(), value.strip()
    if not sep:
        msg = f"trigger {text[:80]!r} is not VAR == value"
        raise FormatError(msg)
    if not var or not all(c.isalnum() or c in "_-.:/" for c in var) or not var.isascii():
        msg = f"trigger {text[:80]!r}: {var[:80]!r} is not a MOOS variable name"
        raise FormatError(msg)
    if not value or not value.isprintable():
        msg = f"trigger {text[:80]!r} has no printable value to compare with"
        raise FormatError(msg)
    if is_moos_numeric(value):
        try:
            number = float(value)
        except ValueError:
            number = math.nan  # "1.2.3" or "-": compared as text
        if math.isfinite(number):
            return Trigger(var, number)
    return Trigger(var, value)


def _error(param: Param, path: str, reason: str) -> MissionError:
    return MissionError(f"{param.name} value {param.value[:80]!r}: {reason}", path, param.lineno)


def _seconds(param: Param, path: str, *, low: float) -> float:
    try:
        value = parse_duration(param.value, name=param.name)
    except FormatError as err:
        raise _error(param, path, err.reason) from None
    if not low <= value <= MAX_SNAPSHOT_SECONDS:
        reason = f"must be from {low:g} s to a day"
        raise _error(param, path, reason)
    return value


def _bytes(param: Param, path: str, *, low: int) -> int:
    try:
        value = parse_size(param.value, name=param.name)
    except FormatError as err:
        raise _error(param, path, err.reason) from None
    if value < low:
        raise _error(param, path, f"must be at least {low} bytes")
    return value


def read_snapshot_settings(block: ProcessBlock | None, path: str) -> SnapshotSettings | None:
    """Read snapshot mode from the pLogger block: None unless ``SnapshotSeconds`` is set.

    Raises:
        MissionError: a value that is not a duration, a size or a trigger, out of range
            (a window of 0.1 s to a day, at least 100 kB of memory), a trigger or another
            snapshot setting without ``SnapshotSeconds``, or more than 16 triggers. The
            message names the file, the line and the setting.
    """
    if block is None:
        return None
    seconds = block.param("SnapshotSeconds")
    others = [p for p in block.params if key(p.name) in _OTHERS]
    if seconds is None:
        if others:
            msg = f"{others[0].name} needs SnapshotSeconds (the window snapshot mode keeps)"
            raise MissionError(msg, path, others[0].lineno)
        return None
    window = _seconds(seconds, path, low=0.1)
    memory = DEFAULT_SNAPSHOT_MEMORY
    if (param := block.param("SnapshotMemory")) is not None:
        memory = _bytes(param, path, low=MIN_SNAPSHOT_MEMORY)
    after = 0.0
    if (param := block.param("SnapshotAfter")) is not None:
        after = _seconds(param, path, low=0.0)
    triggers: list[Trigger] = []
    for param in others:
        if key(param.name) != key("SnapshotTrigger"):
            continue
        try:
            trigger = parse_trigger(param.value)
        except FormatError as err:
            msg = f"{param.name}: {err.reason}"
            raise MissionError(msg, path, param.lineno) from None
        if trigger not in triggers:
            triggers.append(trigger)
        if len(triggers) > MAX_TRIGGERS:
            msg = f"more than {MAX_TRIGGERS} snapshot triggers"
            raise MissionError(msg, path, param.lineno)
    return SnapshotSettings(window, memory, after, tuple(triggers))


def read_disk_settings(block: ProcessBlock | None, path: str) -> DiskSettings:
    """Read ``MinFreeDisk``, ``KeepSessions`` and ``MaxLogSize`` from the pLogger block.

    Raises:
        MissionError: a size that is not one, a ``KeepSessions`` that is not a whole number
            of at least 1, or a ``MaxLogSize`` under 1 MB. The message names the file, the
            line and the setting.
    """
    if block is None:
        return DiskSettings()
    min_free = DEFAULT_MIN_FREE_DISK
    if (param := block.param("MinFreeDisk")) is not None:
        min_free = _bytes(param, path, low=0)
    keep = None
    if (param := block.param("KeepSessions")) is not None:
        text = param.value.strip()
        if not (text.isascii() and text.isdigit() and len(text) <= 7) or not (
            1 <= int(text) <= _MAX_KEEP
        ):
            raise _error(param, path, f"must be a whole number from 1 to {_MAX_KEEP}")
        keep = int(text)
    size = None
    if (param := block.param("MaxLogSize")) is not None:
        size = _bytes(param, path, low=10**6)
    return DiskSettings(min_free, keep, size)


def _option_seconds(text: str, option: str, *, low: float) -> float:
    value = parse_duration(text, name=option)
    if not low <= value <= MAX_SNAPSHOT_SECONDS:
        msg = f"{option} {text.strip()[:80]!r} must be from {low:g} s to a day"
        raise FormatError(msg)
    return value


def with_snapshot_options(
    base: SnapshotSettings | None,
    *,
    seconds: str | None = None,
    memory: str | None = None,
    after: str | None = None,
    triggers: list[str] | tuple[str, ...] = (),
) -> SnapshotSettings | None:
    """Return the mission's snapshot settings with command-line options over them.

    ``--snapshot-seconds`` turns snapshot mode on (``0`` turns the mission's off); a
    ``--snapshot-trigger`` adds to the mission's triggers.

    Raises:
        FormatError: a value that cannot be used; the message names the option.
    """
    if seconds is not None and parse_duration(seconds, name="--snapshot-seconds") == 0:
        return None
    if base is None and seconds is None:
        if memory is not None or after is not None or triggers:
            msg = "--snapshot-memory, --snapshot-after and --snapshot-trigger need snapshot mode"
            raise FormatError(msg + " (--snapshot-seconds, or SnapshotSeconds in the mission)")
        return None
    window = base.seconds if base is not None else 0.0
    if seconds is not None:
        window = _option_seconds(seconds, "--snapshot-seconds", low=0.1)
    size = base.memory if base is not None else DEFAULT_SNAPSHOT_MEMORY
    if memory is not None:
        size = parse_size(memory, name="--snapshot-memory")
        if size < MIN_SNAPSHOT_MEMORY:
            msg = f"--snapshot-memory {memory.strip()[:80]!r} must be at least 100kB"
            raise FormatError(msg)
    later = base.after if base is not None else 0.0
    if after is not None:
        later = _option_seconds(after, "--snapshot-after", low=0.0)
    all_triggers = list(base.triggers) if base is not None else []
    for text in triggers:
        try:
            trigger = parse_trigger(text)
        except FormatError as err:
            msg = f"--snapshot-trigger: {err.reason}"
            raise FormatError(msg) from None
        if trigger not in all_triggers:
            all_triggers.append(trigger)
    if len(all_triggers) > MAX_TRIGGERS:
        msg = f"more than {MAX_TRIGGERS} snapshot triggers"
        raise FormatError(msg)
    return SnapshotSettings(window, size, later, tuple(all_triggers))


def with_disk_options(
    base: DiskSettings,
    *,
    min_free: str | None = None,
    keep_sessions: int | None = None,
    max_log_size: str | None = None,
) -> DiskSettings:
    """Return the mission's disk settings with command-line options over them.

    ``--keep-sessions 0`` and ``--max-log-size 0`` turn the mission's bound off.

    Raises:
        FormatError: a value that cannot be used; the message names the option.
    """
    free = base.min_free if min_free is None else parse_size(min_free, name="--min-free-disk")
    keep = base.keep_sessions
    if keep_sessions is not None:
        if not 0 <= keep_sessions <= _MAX_KEEP:
            msg = f"--keep-sessions {keep_sessions} must be from 0 (no bound) to {_MAX_KEEP}"
            raise FormatError(msg)
        keep = keep_sessions or None
    size = base.max_log_size
    if max_log_size is not None:
        size = parse_size(max_log_size, name="--max-log-size") or None
        if size is not None and size < 10**6:
            msg = (
                f"--max-log-size {max_log_size.strip()[:80]!r} must be 0 (no bound) or at least 1MB"
            )
            raise FormatError(msg)
    return DiskSettings(free, keep, size)
