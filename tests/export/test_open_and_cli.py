"""fleetlog.open on every kind of source, CSV, and the export command's errors."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import polars as pl
import pytest
from export.support import IVP, RUN_A1, THEMOOS, copy_session, expected
from helpers import run_cli

import fleetlog
from fleetlog.errors import UsageError


def alog_of(session: Path) -> Path:
    return next(p for p in session.iterdir() if ".alog" in p.name)


COLUMNS = [
    "vehicle",
    "session",
    "time",
    "offset",
    "variable",
    "source",
    "aux",
    "community",
    "type",
    "double",
    "string",
    "binary",
]


def test_open_an_alog_a_session_an_archive_and_a_parquet_file(tmp_path: Path) -> None:
    by_alog = fleetlog.open(alog_of(IVP))
    by_session = fleetlog.open(IVP)
    assert by_alog.columns == COLUMNS
    assert by_alog.equals(by_session)
    assert by_alog.height == len(expected(alog_of(IVP)))
    assert by_alog["time"].is_sorted()

    archive = tmp_path / "archive"
    copy_session(IVP, archive / "alpha" / IVP.name)
    copy_session(THEMOOS, archive / "bravo" / THEMOOS.name)
    fleet = fleetlog.open(archive)
    assert dict(fleet.group_by("vehicle").len().iter_rows()) == {
        "alpha": len(expected(alog_of(IVP))),
        "bravo": len(expected(alog_of(THEMOOS))),
    }

    out = tmp_path / "fleet.parquet"
    done = run_cli("export", str(archive), "-o", str(out))
    assert done.returncode == 0, done.stderr
    again = fleetlog.open(out)
    assert again.columns == COLUMNS
    assert again.sort("vehicle", "time", "variable").equals(
        fleet.sort("vehicle", "time", "variable")
    )


def test_open_filters_variables_and_times_the_same_on_logs_and_parquet(tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    assert run_cli("export", str(RUN_A1), "-o", str(out)).returncode == 0
    whole = fleetlog.open(RUN_A1)
    start = float(whole["time"][len(whole) // 3])
    end = float(whole["time"][2 * len(whole) // 3])
    for source in (RUN_A1, out):
        part = fleetlog.open(source, variables=["DB_*"], start=start, end=end)
        want = whole.filter(
            pl.col("variable").str.starts_with("DB_") & pl.col("time").is_between(start, end)
        )
        assert part.height == want.height > 0
        assert set(part["variable"]) <= set(want["variable"])


def test_open_gives_pandas(tmp_path: Path) -> None:
    frame = fleetlog.open(IVP, variables=["NAV_X"]).to_pandas()
    assert list(frame["double"]) == [0.0, 0.52211]


def test_csv_rows_of_one_variable(tmp_path: Path) -> None:
    out = tmp_path / "x.csv"
    done = run_cli("export", str(IVP), "-v", "NAV_X", "-o", str(out))
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert [(r["variable"], float(r["value"]), r["vehicle"]) for r in rows] == [
        ("NAV_X", 0.0, "alpha"),
        ("NAV_X", 0.52211, "alpha"),
    ]


def test_csv_table_a_row_per_period(tmp_path: Path) -> None:
    out = tmp_path / "x.csv"
    done = run_cli("export", str(IVP), "--table", "--period", "2", "-v", "NAV_*", "-o", str(out))
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    # offsets 1.35 and 1.85 fall in (0, 2], 2.35 in (2, 4], 5.85 in (4, 6]
    assert [r["time"] for r in rows] == ["2.0", "4.0", "6.0"]
    assert rows[0]["NAV_X"] == "0.0"
    assert rows[1]["NAV_X"] == "0.52211"
    assert rows[2]["NAV_X"] == ""
    assert rows[2]["NAV_LAT"] == "43.82512"
    held = run_cli(
        "export",
        str(IVP),
        "--table",
        "--period",
        "2",
        "--hold",
        "-v",
        "NAV_X",
        "-o",
        str(tmp_path / "h.csv"),
    )
    assert held.returncode == 0, held.stderr
    hold = list(csv.DictReader(io.StringIO((tmp_path / "h.csv").read_text())))
    assert [r["NAV_X"] for r in hold] == ["0.0", "0.52211"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["NOPE", "-o", "x.parquet"], "no such alog, session"),
        ([str(IVP), "-o", "x.txt"], "cannot tell the format"),
        ([str(IVP), "-o", "x.parquet", "--format", "xls"], "--format must be"),
        ([str(IVP), "-o", "x.mcap", "--table"], "are for CSV output"),
        ([str(IVP), "-o", "x.csv", "--table", "--period", "0"], "--period must be a positive"),
        ([str(IVP), "-o", "x.csv", "--table", "--period", "1e-9"], "give a longer --period"),
        ([str(IVP), "-o", "ds/", "-v", "NAV_X"], "a dataset holds whole sessions"),
        ([str(IVP), "-o", "x.parquet", "--from", "@x"], "--from"),
    ],
)
def test_export_errors_are_one_sentence(args: list[str], message: str, tmp_path: Path) -> None:
    done = run_cli("export", *args, cwd=tmp_path)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr
    assert not list(tmp_path.glob("x.*"))
    assert not list(tmp_path.glob(".x.*"))


def test_export_never_overwrites_without_force(tmp_path: Path) -> None:
    out = tmp_path / "x.parquet"
    out.write_bytes(b"precious")
    done = run_cli("export", str(IVP), "-o", str(out))
    assert done.returncode == 1
    assert "give --force" in done.stderr
    assert out.read_bytes() == b"precious"
    forced = run_cli("export", str(IVP), "-o", str(out), "--force")
    assert forced.returncode == 0, forced.stderr
    assert pl.read_parquet(out).height == len(expected(alog_of(IVP)))


def test_open_of_nothing_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(UsageError):
        fleetlog.open(tmp_path)
