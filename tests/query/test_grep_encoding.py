"""The remote grep's batch JSON encoding writes what encode_grep_line writes, record by record."""

from __future__ import annotations

import json
from pathlib import Path

import polars as pl
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.query.grep import _fill, _json_numbers, _json_strings, _record_lines
from fleetlog.storage.columnar import AlogReader
from fleetlog.wire.query import GrepRecord, encode_grep_line

_text = st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)


@given(st.lists(_text, max_size=8))
def test_strings_encode_one_by_one(values: list[str]) -> None:
    assert ['"' + e + '"' for e in _json_strings(values)] == [json.dumps(v) for v in values]


@given(st.lists(st.floats() | st.integers(-(10**20), 10**20), max_size=8))
def test_numbers_encode_one_by_one(values: list[float]) -> None:
    assert _json_numbers(values) == [json.dumps(v) for v in values]


def test_a_batch_encodes_as_each_record_would(tmp_path: Path) -> None:
    fmt = LineFormatter()
    path = tmp_path / "e.alog"
    path.write_text(
        format_banner("./e/e.alog", 1.7e9, "now")
        + fmt.double(0.5, "NAV_X", "p", 1.5)
        + fmt.string(1.0, "Q", 'a","b:aux', 'say "hi", \\ ok é')
        + fmt.string(2.0, "EMPTY", "p", "")
    )
    with AlogReader(path) as reader:
        columns = ("line", "offset", "var", "source", "type", "text")
        got = [
            line.encode("ascii")
            for batch in reader.frames(columns)
            for line in _record_lines(batch).to_list()
        ]
        entries = list(reader.entries())
    kinds = {float: "d", str: "s"}
    expected = [
        encode_grep_line(
            GrepRecord(e.offset, e.key, e.source, kinds[type(e.value)], e.text, e.lineno)
        )
        for e in entries
    ]
    assert got == expected


_names = st.text(
    st.characters(blacklist_categories=("Cs", "Zs", "Cc", "Zl", "Zp")), min_size=1, max_size=10
)
_values = st.text(st.characters(blacklist_categories=("Cs", "Cc", "Zl", "Zp")), max_size=12)
_times = st.sampled_from([0.0, 1e-5, 0.0001, 0.5, 12.25, 1e15, 9.999e15, 1e16, 3e17]) | st.floats(
    0, 1e6, allow_nan=False
).map(lambda t: round(t, 5))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(_times, _names, _names, st.booleans(), st.floats(-1e9, 1e9) | _values),
        min_size=1,
        max_size=30,
    )
)
def test_records_written_by_polars_are_what_each_record_would_be(
    tmp_path_factory: pytest.TempPathFactory,
    rows: list[tuple[float, str, str, bool, float | str]],
) -> None:
    # names, sources and values with quotes, backslashes and non-ASCII (escaped by JSON),
    # and times polars would write otherwise than Python, take the Python path row by row
    fmt = LineFormatter()
    path = tmp_path_factory.mktemp("g") / "g.alog"
    text = format_banner("./g/g.alog", 1.7e9, "now")
    for t, var, source, wide, value in sorted(rows, key=lambda r: r[0]):
        var = var.replace(" ", "_") + ("_" * 30 if wide else "")
        if isinstance(value, float):
            text += fmt.double(t, var, source, value)
        else:
            text += fmt.string(t, var, source, value)
    path.write_text(text, encoding="utf-8")
    with AlogReader(path, errors="skip") as reader:
        columns = ("line", "offset", "var", "source", "type", "text")
        got = [x for b in reader.frames(columns) for x in _record_lines(b).to_list()]
        entries = list(reader.entries())
        kinds = [k for b in reader.frames(("type",)) for k in b.frame["type"].to_list()]
    expected = [
        encode_grep_line(
            GrepRecord(
                e.offset, e.key, e.source, {"double": "d", "string": "s"}[k], e.text, e.lineno
            )
        ).decode("ascii")
        for e, k in zip(entries, kinds, strict=True)
    ]
    assert got == expected


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.integers(1, 300), max_size=60),
    st.integers(0, 400),
    st.integers(64, 1000),
)
def test_replies_end_where_adding_lines_one_by_one_ends_them(
    lengths: list[int], size: int, target: int
) -> None:
    import fleetlog.query.grep as grep

    lines = [("x" * (n - 1)) + "\n" for n in lengths]
    head = [b"h" * size]
    want: list[bytes] = []
    chunk, have = list(head), size
    for line in lines:
        chunk.append(line.encode())
        have += len(line)
        if have >= target:
            want.append(b"".join(chunk))
            chunk, have = [], 0
    got: list[bytes] = []
    mine = list(head)
    old = grep.REPLY_TARGET
    grep.REPLY_TARGET = target
    try:
        left = _fill(pl.Series(lines, dtype=pl.String), mine, size, got.append)
    finally:
        grep.REPLY_TARGET = old
    assert got == want
    assert left == have
    assert b"".join(mine) == b"".join(chunk)
