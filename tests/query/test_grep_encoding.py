"""The remote grep's batch JSON encoding writes what encode_grep_line writes, record by record."""

from __future__ import annotations

import json
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.query.grep import _json_numbers, _json_strings, _record_lines
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
        got = [line for batch in reader.frames(columns) for line in _record_lines(batch)]
        entries = list(reader.entries())
    kinds = {float: "d", str: "s"}
    expected = [
        encode_grep_line(
            GrepRecord(e.offset, e.key, e.source, kinds[type(e.value)], e.text, e.lineno)
        )
        for e in entries
    ]
    assert got == expected
