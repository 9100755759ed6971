"""CSV: the entries one per row, or a synchronous table like pLogger's slog.

* **Rows** (the default; with ``--var NAV_X`` one variable): ``time, offset, vehicle,
  session, variable, source, aux, community, type, value``. A double's value is written in
  full precision, a string as it was (CSV-quoted), a binary as its bytes in base64.
* **Table** (``--table [--period S]``): one row per period and vehicle, one column per
  variable, the way the slog lays out a mission (§3 of MOOS_FORMAT.md): ``time`` is the end
  of the period (seconds since the earliest LOGSTART among the sources, as the slog's TIME
  column; ``epoch`` gives the absolute time), and each cell holds the variable's last value
  posted in that period, or nothing if it was not posted (the slog writes NaN). Unlike the
  slog, strings are kept (a column whose variable is always a double is numeric);
  ``hold=True`` repeats a variable's last value until its next one.

Both stream the logs; the table holds one row per period and variable in memory, never the
entries.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, BinaryIO

from fleetlog.errors import UsageError
from fleetlog.export.entries import Select, Tally, entry_frames
from fleetlog.storage.columnar import Errors

if TYPE_CHECKING:
    import polars as pl

    from fleetlog.export.sources import Source

__all__ = ["write_csv_rows", "write_csv_table"]

#: The most rows a table may have (periods x vehicles): a guard against --period 0.0001.
MAX_TABLE_ROWS = 10_000_000


def _value() -> pl.Expr:
    import polars as pl

    return (
        pl.when(pl.col("type") == "double")
        .then(pl.col("double").cast(pl.String))
        .when(pl.col("type") == "binary")
        .then(pl.col("binary").bin.encode("base64"))
        .otherwise(pl.col("string"))
        .alias("value")
    )


def write_csv_rows(
    sources: Sequence[Source],
    out: BinaryIO,
    tally: Tally,
    *,
    errors: Errors = "skip",
    selection: Select = None,
) -> None:
    """Write the sources' entries as CSV rows, streaming, one header line first.

    Raises:
        StorageError: a log cannot be read or the file written.
        FormatError: (``errors="raise"``) a log is corrupt.
    """
    import polars as pl

    header = True
    for source in sources:
        for frame in entry_frames(source, tally, errors=errors, selection=selection):
            rows = frame.select(
                "time",
                "offset",
                pl.lit(source.vehicle).alias("vehicle"),
                pl.lit(source.session).alias("session"),
                "variable",
                "source",
                "aux",
                "community",
                "type",
                _value(),
            )
            rows.write_csv(out, include_header=header, float_precision=None)
            header = False
    if header:  # nothing at all: still a valid CSV with its header
        out.write(b"time,offset,vehicle,session,variable,source,aux,community,type,value\n")


def write_csv_table(
    sources: Sequence[Source],
    out: BinaryIO,
    tally: Tally,
    *,
    period: float = 1.0,
    hold: bool = False,
    epoch: bool = False,
    errors: Errors = "skip",
    selection: Select = None,
) -> int:
    """Write a synchronous table: a row per period and vehicle, a column per variable.

    Returns:
        The number of rows written.

    Raises:
        UsageError: the period is not a positive number, or makes more than
            :data:`MAX_TABLE_ROWS` rows.
        StorageError: a log cannot be read or the file written.
        FormatError: (``errors="raise"``) a log is corrupt.
    """
    import polars as pl

    if not (math.isfinite(period) and period > 0):
        msg = f"the period must be a positive number of seconds, not {period:g}"
        raise UsageError(msg)
    starts = [s.logstart for s in sources if s.logstart is not None]
    origin = min(starts) if starts else 0.0
    parts: list[pl.DataFrame] = []
    for source in sources:
        for frame in entry_frames(source, tally, errors=errors, selection=selection):
            # The period a value falls in, closed on the right as the slog's rows are
            # written after the values they show: (k-1)p < t <= kp is row k.
            timed = frame.filter(pl.col("time").is_not_null() & pl.col("time").is_finite())
            binned = timed.with_columns(
                row=((pl.col("time") - origin) / period).ceil().cast(pl.Int64, strict=False),
                vehicle=pl.lit(source.vehicle),
                value=_value(),
            ).drop_nulls("row")
            parts.append(
                binned.group_by("vehicle", "row", "variable").agg(
                    pl.col("value").last(), pl.col("time").last(), pl.col("type").last()
                )
            )
    if not parts:
        out.write(b"time,vehicle\n")
        return 0
    cells = pl.concat(parts).sort("time", maintain_order=True)
    cells = cells.group_by("vehicle", "row", "variable", maintain_order=True).agg(
        pl.col("value").last(), pl.col("type").last()
    )
    span = cells.group_by("vehicle").agg(
        pl.col("row").min().alias("lo"), pl.col("row").max().alias("hi")
    )
    total = int(span.select((pl.col("hi") - pl.col("lo") + 1).sum()).item())
    if total > MAX_TABLE_ROWS:
        msg = (
            f"a period of {period:g} s makes {total:,} rows (at most {MAX_TABLE_ROWS:,}):"
            " give a longer --period"
        )
        raise UsageError(msg)
    numeric = cells.group_by("variable").agg((pl.col("type") == "double").all().alias("numeric"))
    doubles = set(numeric.filter("numeric")["variable"].to_list())
    order = sorted(set(cells["variable"].to_list()))
    grid = span.select("vehicle", pl.int_ranges("lo", pl.col("hi") + 1).alias("row")).explode("row")
    wide = cells.pivot(on="variable", index=["vehicle", "row"], values="value")
    table = grid.join(wide, on=["vehicle", "row"], how="left", maintain_order="left")
    if hold:
        table = table.with_columns(pl.col(order).forward_fill().over("vehicle"))
    time = pl.col("row").cast(pl.Float64) * period
    table = table.select(
        (time + origin if epoch else time).alias("time"),
        "vehicle",
        *(pl.col(name).cast(pl.Float64) if name in doubles else pl.col(name) for name in order),
    )
    table.write_csv(out, float_precision=None)
    return table.height
