"""What the tools read: an alog file or a session directory, and the vehicle it belongs to."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.storage.alogscan import HeadInfo, read_head
from fleetlog.storage.columnar import AlogReader, Errors, find_alog

__all__ = ["LogInput", "open_log", "open_log_head"]

_SUFFIXES = (".alog.zst", ".alog.gz", ".alog", ".xlog.zst", ".xlog.gz", ".xlog")


@dataclass
class LogInput:
    """One log to read.

    Attributes:
        name: the input as the user named it.
        path: the alog.
        vehicle: the community of its MOOSDB (``DB_TIME`` from ``MOOSDB_<V>``, or a
            fleetlog recorder's status), else the file's root name.
        time_decimals: decimals of its time column (3 essential-moos, 5 MOOS-IvP).
    """

    name: str
    path: Path
    vehicle: str
    time_decimals: int

    def reader(self, errors: Errors = "raise") -> AlogReader:
        """Open the log (the banner is read now).

        Raises:
            StorageError: the file cannot be read.
            FormatError: (``errors="raise"``) its banner is garbled.
        """
        return AlogReader(self.path, errors=errors)


def _root_name(path: Path) -> str:
    for suffix in _SUFFIXES:
        if path.name.endswith(suffix):
            return path.name[: -len(suffix)]
    return path.stem


def open_log(spec: str | os.PathLike[str], vehicle: str | None = None) -> LogInput:
    """Resolve an alog file or a session directory.

    Raises:
        StorageError: no such file or directory, or a directory without one alog.
    """
    return open_log_head(spec, vehicle)[0]


def open_log_head(
    spec: str | os.PathLike[str], vehicle: str | None = None
) -> tuple[LogInput, HeadInfo]:
    """:func:`open_log`, and the head it read (its banner), for a caller that needs both.

    Raises:
        StorageError: no such file or directory, or a directory without one alog.
    """
    path = Path(spec)
    if path.is_dir():
        path = find_alog(path)
    elif not path.is_file():
        msg = f"{spec}: no such alog or session directory"
        raise StorageError(msg)
    head = read_head(path)
    log = LogInput(
        os.fspath(spec),
        path,
        vehicle or head.community or _root_name(path),
        head.time_decimals if head.time_decimals is not None else 5,
    )
    return log, head
