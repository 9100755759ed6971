"""``fleetlog.open``: logs as one polars DataFrame, for notebooks and scripts.

It takes what the export command takes (an alog, a session, a vehicle's sessions, a shore
archive, several of them) and what it writes (a Parquet file, a fleet dataset), and gives
one table: ``vehicle``, ``session`` and the export columns (:mod:`fleetlog.export.entries`),
in time order. ``variables`` (MOOS globs) and ``start``/``end`` (absolute seconds) are applied
while reading: from alogs before the values are typed, from Parquet through its statistics,
so asking for two variables of a long mission reads little more than those. pandas users
call ``.to_pandas()`` on the result (that needs pandas and pyarrow).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from fleetlog.errors import UsageError
from fleetlog.export.entries import Tally, entry_frames
from fleetlog.export.parquet import schema
from fleetlog.export.sources import Source, resolve
from fleetlog.storage.columnar import Errors
from fleetlog.storage.select import Selection, glob_regex

if TYPE_CHECKING:
    import polars as pl

__all__ = ["open_frame"]

PathLike = str | os.PathLike[str]


def _parquet_files(path: Path) -> list[Path] | None:
    """The Parquet files a path stands for, or None if it is not Parquet."""
    if path.is_file():
        return [path] if path.suffix == ".parquet" else None
    if not path.is_dir():
        return None
    found = sorted(
        p
        for p in path.rglob("*.parquet")
        if not any(part.startswith(".") for part in p.relative_to(path).parts)
    )
    holds_logs = any(
        child.is_dir() and not child.name.startswith(("vehicle=", ".")) for child in path.iterdir()
    )
    return found if found and not holds_logs else None


def _scan(files: list[Path], root: Path) -> pl.LazyFrame:
    import polars as pl

    cols = schema(origin=True)
    hive = root.is_dir() and any("=" in part for f in files for part in f.relative_to(root).parts)
    frame = pl.scan_parquet(
        files,
        hive_partitioning=hive,
        hive_schema={"vehicle": pl.String(), "session": pl.String()} if hive else None,
        missing_columns="insert",
        extra_columns="ignore",
        schema=cols,
    )
    return frame.select(list(cols))


def open_frame(
    source: PathLike | Sequence[PathLike],
    *,
    variables: Sequence[str] = (),
    start: float | None = None,
    end: float | None = None,
    errors: Errors = "skip",
) -> pl.DataFrame:
    """Read logs, a Parquet export or a fleet dataset as one polars DataFrame.

    Args:
        source: a path, or several: alogs, sessions, vehicles' directories, a shore
            archive, a Parquet file or a fleet dataset.
        variables: keep only these variables (MOOS globs: ``NAV_*``).
        start: keep entries at or after this absolute time (seconds since 1970).
        end: keep entries at or before this absolute time.
        errors: ``"skip"`` (count what cannot be read and go on) or ``"raise"``.

    Returns:
        Columns ``vehicle, session, time, offset, variable, source, aux, community, type,
        double, string, binary``, sorted by time (stable).

    Raises:
        UsageError: a path holds nothing to read.
        StorageError: a file cannot be read.
        FormatError: (``errors="raise"``) a log is corrupt.
    """
    import polars as pl

    specs = [source] if isinstance(source, str | os.PathLike) else list(source)
    if not specs:
        msg = "fleetlog.open needs a path"
        raise UsageError(msg)
    frames: list[pl.DataFrame] = []
    logs: list[PathLike] = []
    for spec in specs:
        path = Path(spec)
        files = _parquet_files(path)
        if files is None:
            logs.append(spec)
            continue
        lazy = _scan(files, path if path.is_dir() else path.parent)
        if variables:
            lazy = lazy.filter(
                pl.col("variable").str.contains("|".join(map(glob_regex, variables)))
            )
        if start is not None:
            lazy = lazy.filter(pl.col("time") >= start)
        if end is not None:
            lazy = lazy.filter(pl.col("time") <= end)
        frames.append(lazy.collect())
    if logs:
        frames.extend(_read_logs(resolve(logs).sources, variables, start, end, errors))
    if not frames:
        return pl.DataFrame(schema=schema(origin=True))
    return pl.concat(frames).sort("time", maintain_order=True, nulls_last=True)


def _read_logs(
    sources: list[Source],
    variables: Sequence[str],
    start: float | None,
    end: float | None,
    errors: Errors,
) -> list[pl.DataFrame]:
    import polars as pl

    def select(source: Source) -> Selection | None:
        if not variables and start is None and end is None:
            return None
        if source.logstart is None and (start is not None or end is not None):
            return Selection(variables, (), math.inf, None)  # no absolute times: none match
        base = source.logstart or 0.0
        low = None if start is None else start - base
        high = None if end is None else end - base
        return Selection(variables, (), low, high)

    tally = Tally()
    return [
        frame.select(
            pl.lit(source.vehicle).alias("vehicle"),
            pl.lit(source.session).alias("session"),
            pl.all(),
        )
        for source in sources
        for frame in entry_frames(source, tally, errors=errors, selection=select)
    ]
