"""Exports of hostile logs: an operator's alog, blog or archive may be anything.

Every export of a fuzzed log (valid, cut, corrupted or noise; plain, gz or zst; names with
quotes, commas, ``@``, ``:``, ``/``, newlines and bytes that are not UTF-8) either succeeds
with exactly the entries the columnar reader reads, in files the analysts' readers accept,
or fails with one FleetlogError; binary references that point anywhere (outside the
session, before or past the blog) are counted as missing payloads, never followed.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import shutil
import tempfile
from pathlib import Path

import polars as pl
import pyarrow.parquet as pq
import pytest
from hostile import alog_files, hostile_text
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from fleetlog.errors import FleetlogError
from fleetlog.export import Tally, export_mcap, resolve, write_csv_rows, write_parquet
from fleetlog.moos.alog import LineFormatter, format_banner, format_entry
from fleetlog.storage.columnar import AlogReader

CASES = settings(
    max_examples=40, deadline=None, database=None, suppress_health_check=list(HealthCheck)
)


def _reader_rows(path: Path) -> list[tuple[float, str]]:
    with AlogReader(path, errors="skip") as reader:
        return [
            (offset, var)
            for batch in reader.batches(("offset", "var"))
            for offset, var in batch.iter_rows()
        ]


def _export_all(path: Path, where: Path) -> None:
    sources = resolve([path]).sources
    want = _reader_rows(sources[0].path)
    tally = Tally()
    parquet = where / "x.parquet"
    with parquet.open("wb") as f:
        write_parquet(sources, f, tally)
    assert tally.entries == len(want)
    got = pl.read_parquet(parquet).select("offset", "variable").rows()
    assert sorted(got, key=repr) == sorted(want, key=repr)
    assert pq.read_table(parquet).num_rows == len(want)

    tally = Tally()
    mcap = where / "x.mcap"
    with mcap.open("wb") as f:
        result = export_mcap(sources, f, tally)
    with mcap.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        plain = 0
        for schema, _, message in reader.iter_messages():
            data = json.loads(message.data)
            if schema is not None and schema.name == "fleetlog.MoosValue":
                plain += 1
                assert set(data) == {"value", "source", "aux", "community"}
    assert plain + result.untimed == len(want)

    tally = Tally()
    text = io.BytesIO()
    write_csv_rows(sources, text, tally)
    rows = list(csv.DictReader(io.StringIO(text.getvalue().decode())))
    assert len(rows) == len(want)


@CASES
@given(alog_files())
def test_fuzzed_logs_export_or_fail_cleanly(case: tuple[str, bytes]) -> None:
    suffix, data = case
    where = Path(tempfile.mkdtemp(prefix="fleetlog-export-fuzz-"))
    try:
        path = where / ("S" + suffix)
        path.write_bytes(data)
        # a compressed stream that is not one, say: one FleetlogError, no other exception
        with contextlib.suppress(FleetlogError):
            _export_all(path, where)
    finally:
        shutil.rmtree(where, ignore_errors=True)


_FILES = st.sampled_from(["S.blog", "../S.blog", "/etc/hostname", "", "..", "S.alog", "nope"])


@CASES
@given(
    refs=st.lists(
        st.tuples(
            _FILES,
            st.sampled_from([-1, 0, 1, 5, 10**12, 2**63 - 1]) | st.integers(0, 64),
            st.sampled_from([0, 1, 10**12]) | st.integers(0, 64),
        ),
        max_size=6,
    ),
    blog=st.binary(max_size=64),
    names=st.lists(hostile_text, max_size=3),
)
def test_binary_references_are_never_followed_out_of_the_session(
    refs: list[tuple[str, int, int]], blog: bytes, names: list[str]
) -> None:
    where = Path(tempfile.mkdtemp(prefix="fleetlog-export-fuzz-"))
    try:
        session = where / "S"
        session.mkdir()
        (session / "S.blog").write_bytes(blog)
        (where / "S.blog").write_bytes(b"outside the session " * 8)
        fmt = LineFormatter()
        lines = [format_banner("./S/S.alog", 1.8e9, "Thu Jan  1 00:00:00 1970")]
        for i, (file, offset, size) in enumerate(refs):
            tag = f"<MOOS_BINARY>File={file},Offset={offset},Bytes={size}</MOOS_BINARY>"
            lines.append(format_entry(float(i), "CAMERA", "iCam", tag, binary=True))
        for i, name in enumerate(names):
            lines.append(fmt.string(10.0 + i, "NOTE", "pX", name.replace("\n", " ")))
        (session / "S.alog").write_text("".join(lines), "utf-8", "surrogateescape")
        tally = Tally()
        out = where / "x.parquet"
        with out.open("wb") as f:
            write_parquet(resolve([session]).sources, f, tally)
        frame = pl.read_parquet(out).filter(pl.col("type") == "binary")
        assert frame.height == len(refs)
        present = frame.filter(pl.col("binary").is_not_null())
        assert present.height + tally.payloads_missing == len(refs)
        inside = {p.name: p.read_bytes() for p in session.iterdir()}
        for payload, ref in present.select("binary", "string").iter_rows():
            # only a file beside the log, named bare, is ever read
            name = ref.removeprefix("<MOOS_BINARY>File=").split(",")[0]
            assert name in inside
            assert payload in inside[name]
        _export_all(session, where)
    finally:
        shutil.rmtree(where, ignore_errors=True)


def test_a_forged_size_is_an_error_not_a_memory_error(tmp_path: Path) -> None:
    (tmp_path / "S.blog").write_bytes(b"abc\n")
    tag = "<MOOS_BINARY>File=S.blog,Offset=0,Bytes=1000000000000</MOOS_BINARY>"
    alog = tmp_path / "S.alog"
    alog.write_text(
        format_banner("./S.alog", 1.8e9, "Thu Jan  1 00:00:00 1970")
        + format_entry(1.0, "CAMERA", "iCam", tag, binary=True)
    )
    with AlogReader(alog) as reader:
        entry = next(reader.entries())
        with pytest.raises(FleetlogError, match="ends before"):
            reader.read_binary(entry)
