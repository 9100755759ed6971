"""What an export reads: an alog, a session, a vehicle's sessions, or a shore archive.

A SOURCE is resolved by what it holds, not by its name:

* a file is an alog (``.alog``, ``.alog.gz``, ``.alog.zst``, or an ``.xlog``);
* a directory that holds an alog is a session;
* a directory whose sub-directories are sessions is one vehicle's sessions (``VEHICLE/``);
* a directory whose sub-directories are vehicles is a shore archive, the layout ``fleetlog
  fetch --all`` and the collector write: ``ARCHIVE/VEHICLE/SESSION/``.

In an archive the directory names are the vehicles (the fleet's names, which the shore
checked); elsewhere the vehicle is the log's MOOS community, as ``fleetlog merge`` finds it.
A session whose alog is still a ``.part`` (a fetch not finished) is not a session yet: it is
listed in :attr:`Resolved.pending` so that the caller says so, and picked up next time.
Hidden entries (``.NAME``) are never read. Only two levels below SOURCE are looked at.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import StorageError, UsageError
from fleetlog.tools.inputs import open_log_head

__all__ = ["Resolved", "Source", "resolve"]

_ALOG = (".alog", ".alog.gz", ".alog.zst")
_LOGS = (*_ALOG, ".xlog", ".xlog.gz", ".xlog.zst")
#: Directories looked at in one archive at most (a stray home directory is not an archive).
MAX_DIRS = 100_000


@dataclass(frozen=True, slots=True)
class Source:
    """One log to export.

    Attributes:
        vehicle: the vehicle it belongs to.
        session: the session's name (its directory, or the alog's root name).
        path: the alog.
        logstart: the banner's LOGSTART, or None without a usable banner.
    """

    vehicle: str
    session: str
    path: Path
    logstart: float | None


@dataclass
class Resolved:
    """The logs SOURCE(s) name, in vehicle then LOGSTART order.

    Attributes:
        sources: the logs.
        pending: session directories skipped because their alog is not complete yet.
    """

    sources: list[Source] = field(default_factory=list)
    pending: list[Path] = field(default_factory=list)

    @property
    def vehicles(self) -> list[str]:
        """The vehicles, each once, in order."""
        return list(dict.fromkeys(s.vehicle for s in self.sources))


def _visible(directory: Path) -> list[Path]:
    try:
        return sorted(c for c in directory.iterdir() if not c.name.startswith("."))
    except OSError as err:
        msg = f"cannot list {directory}: {err.strerror or err}"
        raise StorageError(msg) from None


def _holds_alog(directory: Path) -> bool:
    return any(c.name.endswith(_ALOG) and c.is_file() for c in _visible(directory))


def _is_pending(directory: Path) -> bool:
    return any(c.name.endswith(tuple(s + ".part" for s in _ALOG)) for c in _visible(directory))


def _root_name(path: Path) -> str:
    for suffix in _LOGS:
        if path.name.endswith(suffix):
            return path.name[: -len(suffix)]
    return path.stem


def _session(directory: Path, vehicle: str) -> Source:
    log, head = open_log_head(directory, vehicle)  # the head is read once
    return Source(
        log.vehicle, directory.name, log.path, head.banner.logstart if head.banner else None
    )


def _vehicle_dir(directory: Path, vehicle: str, out: Resolved, budget: list[int]) -> bool:
    """Add the sessions of a vehicle's directory; False if it holds none."""
    found = False
    for child in _visible(directory):
        budget[0] -= 1
        if budget[0] < 0:
            msg = f"more than {MAX_DIRS} directories under the source: is it an archive?"
            raise UsageError(msg)
        if not child.is_dir():
            continue
        if _holds_alog(child):
            out.sources.append(_session(child, vehicle))
            found = True
        elif _is_pending(child):
            out.pending.append(child)
            found = True
    return found


def _add(spec: str | os.PathLike[str], out: Resolved) -> None:
    path = Path(spec)
    if path.is_file():
        log, head = open_log_head(path)
        out.sources.append(
            Source(
                log.vehicle,
                _root_name(path),
                path,
                head.banner.logstart if head.banner else None,
            )
        )
        return
    if not path.is_dir():
        msg = f"{spec}: no such alog, session, vehicle directory or archive"
        raise UsageError(msg)
    if _holds_alog(path):
        out.sources.append(_session(path, ""))
        return
    budget = [MAX_DIRS]
    if _vehicle_dir(path, path.resolve().name, out, budget):
        return
    found = False
    for child in _visible(path):
        if child.is_dir() and _vehicle_dir(child, child.name, out, budget):
            found = True
    if not found:
        msg = f"{spec} holds no alog, session, vehicle's sessions or archive of vehicles"
        raise UsageError(msg)


def resolve(specs: list[str | os.PathLike[str]] | list[str]) -> Resolved:
    """Resolve SOURCE arguments into the logs they hold.

    Raises:
        UsageError: a SOURCE is missing or holds no log.
        StorageError: a directory or log cannot be read.
    """
    if not specs:
        msg = "name at least one SOURCE: an alog, a session, a vehicle's sessions or an archive"
        raise UsageError(msg)
    out = Resolved()
    for spec in specs:
        _add(spec, out)
    seen: set[tuple[str, Path]] = set()
    unique = []
    for source in out.sources:
        key = (source.vehicle, source.path.resolve())
        if key not in seen:
            seen.add(key)
            unique.append(source)
    order = {vehicle: i for i, vehicle in enumerate(dict.fromkeys(s.vehicle for s in unique))}
    unique.sort(
        key=lambda s: (order[s.vehicle], s.logstart if s.logstart is not None else 0.0, s.session)
    )
    out.sources = unique
    return out
