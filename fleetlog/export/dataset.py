"""A fleet dataset: a shore archive as one hive-partitioned Parquet table, grown in place.

``ARCHIVE/VEHICLE/SESSION/`` becomes ``DATASET/vehicle=VEHICLE/session=SESSION/entries.parquet``
(partition values percent-encoded, as hive readers decode them). Each session is one file of
:mod:`fleetlog.export.parquet`'s rows, without ``vehicle`` and ``session`` columns (they are
the partitions), so DuckDB, polars or Spark read the fleet's history as one table::

    pl.scan_parquet("DATASET/**/*.parquet", hive_partitioning=True)
    SELECT vehicle, count(*) FROM read_parquet('DATASET/**/*.parquet', hive_partitioning=true)
        GROUP BY vehicle

Incremental: a session whose file exists is never written again, and a file appears whole or
not at all (written hidden beside it, then renamed), so an interrupted export leaves the
dataset valid and the next run finishes it. Each file carries its provenance in its Parquet
metadata (the alog's name, size and modification time); a session whose alog changed since
(a fetch that completed a session cut short) is reported, not rewritten: delete its
directory to export it again. Nothing else is ever written into the dataset's tree, so
``scan_parquet(DATASET)`` works too.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

from fleetlog.errors import StorageError
from fleetlog.export.entries import Tally
from fleetlog.export.parquet import write_parquet
from fleetlog.export.sources import Resolved, Source
from fleetlog.storage.columnar import Errors
from fleetlog.storage.outputs import atomic_output

__all__ = ["FILE_NAME", "DatasetResult", "export_dataset", "partition_dir"]

#: The one file of a session's partition.
FILE_NAME = "entries.parquet"
_STAMP = "fleetlog.alog"


@dataclass
class DatasetResult:
    """What a dataset export did.

    Attributes:
        written: ``(vehicle, session, entries)`` of the sessions exported now.
        kept: sessions already in the dataset (left as they were).
        changed: sessions already in the dataset whose alog changed since.
        pending: session directories whose alog is not complete yet (not exported).
        tally: what reading the new sessions met.
    """

    written: list[tuple[str, str, int]] = field(default_factory=list)
    kept: list[tuple[str, str]] = field(default_factory=list)
    changed: list[tuple[str, str]] = field(default_factory=list)
    pending: list[Path] = field(default_factory=list)
    tally: Tally = field(default_factory=Tally)


def partition_dir(dataset: Path, vehicle: str, session: str) -> Path:
    """Return a session's directory in the dataset (values percent-encoded, hive style)."""
    return dataset / f"vehicle={quote(vehicle, safe='')}" / f"session={quote(session, safe='')}"


def _stamp(source: Source) -> dict[str, object]:
    try:
        st = source.path.stat()
    except OSError as err:
        msg = f"cannot read {source.path}: {err.strerror or err}"
        raise StorageError(msg) from None
    return {"name": source.path.name, "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _recorded(path: Path) -> dict[str, object] | None:
    import polars as pl

    try:
        meta = pl.read_parquet_metadata(path)
        found = json.loads(meta.get(_STAMP, "null"))
    except (OSError, ValueError, pl.exceptions.PolarsError):
        return None
    return found if isinstance(found, dict) else None


def export_dataset(
    resolved: Resolved,
    dataset: Path,
    *,
    errors: Errors = "skip",
    on_session: object = None,
) -> DatasetResult:
    """Add the sessions of ``resolved`` that are not in ``dataset`` yet.

    Args:
        resolved: the archive's sessions.
        dataset: the dataset's directory (made if missing).
        errors: the reader's error policy.
        on_session: called as ``on_session(vehicle, session)`` before each new session.

    Raises:
        StorageError: a log cannot be read or a file written (the sessions written before
            stay, complete).
        FormatError: (``errors="raise"``) a log is corrupt.
    """
    if dataset.exists() and not dataset.is_dir():
        msg = f"{dataset} is a file; a dataset is a directory"
        raise StorageError(msg)
    result = DatasetResult(pending=list(resolved.pending))
    for source in resolved.sources:
        target = partition_dir(dataset, source.vehicle, source.session) / FILE_NAME
        stamp = _stamp(source)
        if target.exists():
            recorded = _recorded(target)
            pair = (source.vehicle, source.session)
            result.kept.append(pair)
            if recorded is not None and recorded != stamp:
                result.changed.append(pair)
            continue
        if callable(on_session):
            on_session(source.vehicle, source.session)
        before = result.tally.entries
        with atomic_output(target) as out:
            write_parquet(
                [source],
                out,
                result.tally,
                origin=False,
                errors=errors,
                extra_metadata={_STAMP: json.dumps(stamp)},
            )
        result.written.append((source.vehicle, source.session, result.tally.entries - before))
    return result


def dataset_files(dataset: Path) -> list[Path]:
    """Return the dataset's session files (for a reader that wants the list)."""
    out: list[Path] = []
    for root, dirs, files in os.walk(dataset):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        out.extend(Path(root) / name for name in sorted(files) if name == FILE_NAME)
    return out
