"""Parquet exports re-read by polars, pyarrow and pandas: the alog's values, types and times."""

from __future__ import annotations

import itertools
from pathlib import Path

import pandas as pd
import polars as pl
import pyarrow.parquet as pq
import pytest
from export.support import IVP, REFERENCE_ALOGS, Expected, expected, same_double
from helpers import REFERENCE

from fleetlog.export import Tally, resolve, write_parquet
from fleetlog.storage.outputs import atomic_output


def export(sources: list[Path], out: Path, **options: object) -> Tally:
    tally = Tally()
    with atomic_output(out) as f:
        write_parquet(resolve(sources).sources, f, tally, **options)  # type: ignore[arg-type]
    return tally


def rows_of(frame: pl.DataFrame) -> list[tuple[object, ...]]:
    return list(
        frame.select(
            "offset",
            "time",
            "variable",
            "source",
            "aux",
            "community",
            "type",
            "double",
            "string",
            "binary",
        ).iter_rows()
    )


def check(rows: list[tuple[object, ...]], want: list[Expected]) -> None:
    # The file is ordered by variable (row groups skip by name); the oracle by line.
    def key(r: tuple[object, ...]) -> tuple[str, float]:
        return (str(r[2]), float(r[0]))  # type: ignore[arg-type]

    got = sorted(rows, key=key)
    ref = sorted(
        (
            (
                w.offset,
                w.time,
                w.variable,
                w.source,
                w.aux,
                w.community,
                w.type,
                w.double,
                w.string,
                w.binary,
            )
            for w in want
        ),
        key=key,
    )
    assert len(got) == len(ref)
    for g, r in zip(got, ref, strict=True):
        assert g[0] == r[0]
        assert g[1] == r[1]
        assert g[2:7] == r[2:7]
        assert same_double(g[7], r[7]), (g, r)  # type: ignore[arg-type]
        assert g[8:] == r[8:], (g, r)


@pytest.mark.parametrize("alog", REFERENCE_ALOGS, ids=lambda p: p.parent.name)
def test_parquet_round_trip_through_polars_pyarrow_and_pandas(alog: Path, tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    tally = export([alog], out)
    want = expected(alog)
    assert tally.entries == len(want)

    check(rows_of(pl.read_parquet(out)), want)

    table = pq.read_table(out)
    assert table.schema.field("time").type == "double"
    assert table.schema.field("variable").type in ("string", "large_string")
    check(rows_of(pl.from_arrow(table)), want)  # type: ignore[arg-type]

    frame = pd.read_parquet(out)
    assert len(frame) == len(want)
    by_var = frame.groupby("variable").size().to_dict()
    counts: dict[str, int] = {}
    for w in want:
        counts[w.variable] = counts.get(w.variable, 0) + 1
    assert by_var == counts
    doubles = frame[frame["type"] == "double"]
    assert doubles["double"].notna().sum() + doubles["double"].isna().sum() == sum(
        1 for w in want if w.type == "double"
    )


def test_binary_payloads_come_from_the_blog(tmp_path: Path) -> None:
    alog = REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07"
    out = tmp_path / "x.parquet"
    export([alog], out)
    frame = pl.read_parquet(out).filter(pl.col("type") == "binary")
    assert frame.height == 2
    blog = next(alog.glob("*.blog")).read_bytes()
    for payload, ref in frame.select("binary", "string").iter_rows():
        assert payload
        assert payload in blog
        assert ref.startswith("<MOOS_BINARY>")


def test_row_groups_have_statistics_that_skip_by_variable_and_time(tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    export([REFERENCE_ALOGS[0]], out, row_group=16)
    meta = pq.ParquetFile(out).metadata
    assert meta.num_row_groups > 2
    names = [meta.schema.column(i).name for i in range(meta.num_columns)]
    var, time = names.index("variable"), names.index("time")
    spans = []
    for g in range(meta.num_row_groups):
        stats = meta.row_group(g).column(var).statistics
        assert stats is not None
        assert stats.has_min_max
        assert meta.row_group(g).column(time).statistics.has_min_max
        spans.append((stats.min, stats.max))
    # ordered by variable: the row groups' name ranges follow each other without overlap
    assert all(a[1] <= b[0] for a, b in itertools.pairwise(spans))
    # so a reader looking for one variable reads few row groups
    wanted = spans[len(spans) // 2][0]
    hit = [s for s in spans if s[0] <= wanted <= s[1]]
    assert len(hit) < len(spans) / 2


def test_several_vehicles_in_one_file_carry_vehicle_and_session(tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    alogs = [IVP, REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07"]
    export(alogs, out)
    frame = pl.read_parquet(out)
    counts = dict(frame.group_by("session").len().iter_rows())
    assert counts == {
        IVP.name: len(expected(next(IVP.glob("*.alog")))),
        alogs[1].name: len(expected(next(alogs[1].glob("*.alog")))),
    }
    assert set(frame["vehicle"].unique()) == {"alpha", alogs[1].name}
    meta = pq.ParquetFile(out).metadata.metadata
    assert b"fleetlog.sources" in meta
