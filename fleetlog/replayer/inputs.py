"""What the player replays: alogs and session directories, each with the vehicle it belongs to.

An input is an alog (``.alog``, ``.alog.gz``, ``.alog.zst``) or a session directory (its alog
is found by :func:`fleetlog.storage.readers.find_alog`). Its vehicle, under which its entries
are published, is decided in this order:

1. ``--as V`` (the caller's override);
2. the community of the MOOSDB that logged it: the source ``MOOSDB_<V>`` of a ``DB_TIME``
   line among the first entries (every MOOSDB posts DB_TIME about once a second and names
   itself ``MOOSDB_<Community>``);
3. the ``Community`` of the mission copy ``<root>._moos`` beside the alog.

A session recorded by ``fleetlog record`` without a mission has neither, so it needs ``--as``.
Nothing here loads a whole file: the vehicle scan reads a bounded number of entries and the
end time of a plain alog comes from its last 64 KiB.
"""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from fleetlog.errors import FormatError, ReplayError, StorageError
from fleetlog.moos.alog import BANNER_RULE
from fleetlog.moos.mission import parse_mission
from fleetlog.storage.columnar import read_tail
from fleetlog.storage.metafile import read_meta
from fleetlog.storage.readers import AlogReader, Errors, find_alog, open_text

__all__ = [
    "RemoteSpec",
    "ReplayInput",
    "alog_root",
    "clock_warnings",
    "detect_vehicle",
    "open_input",
    "open_inputs",
    "parse_remote",
]

#: The vehicle in a fleetlog recorder's status line (``...,Community=alpha,...``).
STATUS_COMMUNITY = re.compile(r"(?:^|,)Community=([^,]*)")
#: Entries scanned for a ``DB_TIME`` line from ``MOOSDB_<V>`` when looking for the vehicle.
VEHICLE_SCAN_ENTRIES = 5000
#: Bytes read from the end of a plain alog to find its last entry time.
TAIL_BYTES = 64 * 1024
#: The reader's block for replay: small enough that parsing one (on a worker thread, ahead
#: of the player) is quick, large enough to keep the reader fast.
REPLAY_BLOCK = 1 << 20
_ALOG_SUFFIXES = (".alog.zst", ".alog.gz", ".alog")
_REMOTE_RE = re.compile(r"(?P<vehicle>[^/:]+):(?P<session>[^/]+)")


@dataclass(frozen=True, slots=True)
class RemoteSpec:
    """A remote input, ``V:latest`` or ``V:SESSION``, served by a vehicle's query service."""

    vehicle: str
    session: str


def parse_remote(spec: str) -> RemoteSpec | None:
    """Return the remote session ``spec`` names, or None when it is a local path.

    A spec is remote when it has the shape ``VEHICLE:SESSION`` (no ``/``) and no file or
    directory of that name exists.
    """
    if os.path.exists(spec):
        return None
    match = _REMOTE_RE.fullmatch(spec)
    if match is None:
        return None
    return RemoteSpec(match.group("vehicle"), match.group("session"))


def alog_root(alog: Path) -> str:
    """Return the session root of an alog's name (``root`` of ``root.alog.gz``)."""
    name = alog.name
    for suffix in _ALOG_SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return alog.stem


@dataclass
class ReplayInput:
    """One alog to replay, open, with the vehicle its entries are published under.

    Attributes:
        name: the input as the user gave it (for messages and the summary).
        reader: the open reader (one pass per replay pass; binary values are read from it).
        vehicle: the vehicle the entries belong to (before any ``--prefix``).
        vehicle_from: how the vehicle was found: ``--as``, ``DB_TIME`` or ``._moos``.
        logstart: the banner's LOGSTART (absolute time of offset 0).
        end: the absolute time of the last entry, when it can be known cheaply (a plain
            alog); None for compressed alogs.
        synced: whether the recording host's clock was synchronised when the session
            opened, from fleetlog's session metadata beside the alog (None: not known, as
            for a log written by pLogger).
    """

    name: str
    reader: AlogReader
    vehicle: str
    vehicle_from: str
    logstart: float
    end: float | None
    synced: bool | None = None

    @property
    def path(self) -> Path:
        """The alog file."""
        return self.reader.path

    def close(self) -> None:
        """Close the reader."""
        self.reader.close()


def _moos_community(alog: Path) -> str | None:
    """Return the ``Community`` of the ``._moos`` mission copy beside an alog, if any."""
    moos = alog.with_name(alog_root(alog) + "._moos")
    if not moos.is_file():
        return None
    try:
        with open_text(moos) as text:
            # A mission file, not a log: bounded anyway, in case the name lies.
            lines = list(itertools.islice(text, 100_000))
    except StorageError:
        return None
    if lines and lines[0].rstrip("\n") == BANNER_RULE:
        # pLogger's banner comes first (§1.5): drop it, up to its closing rule.
        for index, line in enumerate(lines[1:], start=1):
            if line.rstrip("\n") == BANNER_RULE:
                lines = lines[index + 1 :]
                break
    try:
        return parse_mission("".join(lines), str(moos)).community
    except FormatError:
        return None


def _db_time_community(reader: AlogReader) -> tuple[str, str] | None:
    """Return ``V`` of the first ``DB_TIME`` posted by ``MOOSDB_<V>`` among the first entries.

    Failing that, the ``Community=V`` field of a fleetlog recorder's ``<APP>_STATUS`` (a
    session recorded without a mission has no ``._moos`` and no MOOSDB).
    """
    entries = reader.entries()
    status: str | None = None
    try:
        for entry in itertools.islice(entries, VEHICLE_SCAN_ENTRIES):
            if entry.key == "DB_TIME" and entry.source.startswith("MOOSDB_"):
                community = entry.source[len("MOOSDB_") :]
                if community:
                    return community, "DB_TIME"
            elif status is None and entry.key.endswith("_STATUS") and isinstance(entry.value, str):
                found = STATUS_COMMUNITY.search(entry.value)
                if found and found.group(1):
                    status = found.group(1)
    finally:
        close = getattr(entries, "close", None)
        if close is not None:
            close()
    return (status, "status") if status is not None else None


def detect_vehicle(reader: AlogReader) -> tuple[str, str] | None:
    """Return ``(vehicle, how)`` for an alog from its DB_TIME or status lines or its ``._moos``.

    Raises:
        FormatError: (a ``"raise"`` reader) a malformed line among the entries scanned;
            better said now, naming the file and line, than as "no vehicle".
        StorageError: the alog cannot be read.
    """
    found = _db_time_community(reader)
    if found is not None:
        return found
    community = _moos_community(reader.path)
    if community is not None:
        return community, "._moos"
    return None


def _tail_end(reader: AlogReader) -> float | None:
    """Return LOGSTART + the largest offset among the last 64 KiB of a plain alog."""
    logstart = reader.logstart
    if logstart is None or reader.compression:
        return None
    try:
        offsets = read_tail(reader.path, TAIL_BYTES)["offset"]
    except StorageError:
        return None
    return logstart + float(offsets.max()) if offsets.len() else None  # type: ignore[arg-type]


def clock_warnings(inputs: Sequence[ReplayInput]) -> list[str]:
    """What to warn of before a fleet replay: vehicles whose clock was not synchronised.

    Several vehicles play on one clock by their absolute times; one whose clock was not
    synchronised when its session opened (fleetlog's session metadata says so) may be
    placed seconds away from the others. One vehicle alone plays right whatever its clock.
    """
    if len({item.vehicle for item in inputs}) < 2:
        return []
    return [
        f"{item.vehicle}'s clock was not synchronised when {item.name} was recorded: on one"
        " clock with the other vehicles, its entries may be out of place by as much as its"
        " clock was off"
        for item in inputs
        if item.synced is False
    ]


def _clock_synced(reader: AlogReader) -> bool | None:
    """Whether the session's clock was synchronised at open, from its metadata (if any).

    A metadata file that cannot be read says nothing: the replay does not need it.
    """
    try:
        meta = read_meta(reader.path.parent)
    except (StorageError, FormatError):
        return None
    synced = meta.clock.get("synchronized") if meta is not None else None
    return synced if isinstance(synced, bool) else None


def _alog_of(spec: str) -> Path:
    path = Path(spec)
    if path.is_dir():
        return find_alog(path)
    if path.is_file():
        return path
    if parse_remote(spec) is not None:
        msg = f"{spec}: a remote input, but no way to fetch it was given (open_inputs(fetch=...))"
        raise ReplayError(msg)
    msg = f"{spec}: no such file or session directory"
    raise ReplayError(msg)


def open_input(
    spec: str | os.PathLike[str],
    vehicle: str | None = None,
    *,
    errors: Errors = "raise",
    how: str = "--as",
    name: str | None = None,
    block_size: int = REPLAY_BLOCK,
) -> ReplayInput:
    """Open one input: check its banner, find its vehicle and, if cheap, its end time.

    Args:
        spec: an alog file or a session directory.
        vehicle: the vehicle to publish as (``--as``); found from the log when None.
        errors: the reader's error policy for bad lines (``"raise"`` or ``"skip"``).
        how: how ``vehicle`` was chosen, for the summary.
        name: the input as the user named it (the spec by default).
        block_size: the reader's block (see :class:`~fleetlog.storage.columnar.AlogReader`).

    Raises:
        ReplayError: the input does not exist, or its vehicle cannot be found.
        StorageError: the file cannot be read, or has no usable LOGSTART.
        FormatError: the banner is garbled (the message names the file and line).
    """
    path = os.fspath(spec)
    name = path if name is None else name
    reader = AlogReader(_alog_of(path), errors=errors, block_size=block_size)
    try:
        logstart, found = _identify(reader, name, vehicle, how)
        end = _tail_end(reader)
        return ReplayInput(name, reader, found[0], found[1], logstart, end, _clock_synced(reader))
    except BaseException:
        reader.close()
        raise


def _identify(
    reader: AlogReader, name: str, vehicle: str | None, how: str
) -> tuple[float, tuple[str, str]]:
    """Return the input's LOGSTART and ``(vehicle, how it was found)``."""
    logstart = reader.logstart
    if logstart is None:
        msg = f"{reader.path}: no usable banner, so its entries have no absolute time"
        raise StorageError(msg)
    found = (vehicle, how) if vehicle is not None else detect_vehicle(reader)
    if found is None:
        msg = (
            f"{name}: cannot tell which vehicle this log is from (no DB_TIME from"
            " MOOSDB_<V>, no Community in a ._moos); name it with --as V"
        )
        raise ReplayError(msg)
    return logstart, found


def open_inputs(
    specs: Sequence[str | os.PathLike[str]],
    vehicles: Sequence[str] = (),
    *,
    errors: Errors = "raise",
    fetch: Callable[[RemoteSpec], Path] | None = None,
    block_size: int = REPLAY_BLOCK,
) -> list[ReplayInput]:
    """Open several inputs; ``vehicles`` is empty, one name for all, or one per input.

    Args:
        specs: alogs, session directories, and (with ``fetch``) remote sessions.
        vehicles: ``--as``.
        errors: the readers' error policy.
        fetch: brings a remote session (``V:latest``, ``V:SESSION``) into a local directory;
            without it a remote input is refused. Its vehicle is ``V`` unless ``--as``.
        block_size: the readers' block.

    Raises:
        ReplayError: no inputs, a wrong number of vehicle names, or as :func:`open_input`.
        StorageError: as :func:`open_input`.
        FormatError: as :func:`open_input`.
        QueryError: a remote session could not be fetched.
    """
    if not specs:
        msg = "nothing to replay: give at least one alog or session directory"
        raise ReplayError(msg)
    if len(vehicles) not in (0, 1, len(specs)):
        msg = (
            f"--as was given {len(vehicles)} times for {len(specs)} inputs: give it once (for"
            " every input) or once per input"
        )
        raise ReplayError(msg)
    names: list[str | None]
    if not vehicles:
        names = [None] * len(specs)
    elif len(vehicles) == 1:
        names = [vehicles[0]] * len(specs)
    else:
        names = list(vehicles)
    opened: list[ReplayInput] = []
    try:
        for spec, vehicle in zip(specs, names, strict=True):
            remote = parse_remote(os.fspath(spec)) if fetch is not None else None
            if fetch is not None and remote is not None:
                local = fetch(remote)
                how = "--as" if vehicle is not None else "remote"
                chosen = remote.vehicle if vehicle is None else vehicle
                opened.append(
                    open_input(
                        local,
                        chosen,
                        errors=errors,
                        how=how,
                        name=os.fspath(spec),
                        block_size=block_size,
                    )
                )
            else:
                opened.append(open_input(spec, vehicle, errors=errors, block_size=block_size))
    except BaseException:
        for item in opened:
            item.close()
        raise
    return opened
