"""A selective read (a grep's literals) gives exactly what reading every line gives.

With a :class:`Selection` whose globs hold a literal, the reader cuts the fields of only the
lines that hold it, in blocks that prove they have no continuation or stray line (each line
an entry or a comment, by :func:`entry_line`). Here the same selection is read both ways
(as a plain function, the reader cannot see its literals) on generated logs with and without
continuation lines, fields wider than their columns, bytes that are not UTF-8, DATATYPE
MARKING and cut tails, and must give the same entries, counts and errors; variable globs are
also checked against the line parser (tests/alog_oracle.py).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import polars as pl
import pytest
from alog_cases import NAMES, SOURCES, alog_bytes
from alog_oracle import AlogReader as OracleReader
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FleetlogError
from fleetlog.moos.alog import Entry
from fleetlog.moos.patterns import glob_match
from fleetlog.storage import alogpass
from fleetlog.storage.alogfields import entry_line, overflow_fields, standard_layout
from fleetlog.storage.columnar import AlogReader
from fleetlog.storage.select import Selection, glob_literal

_COLUMNS = ("line", "offset", "var", "source", "type", "double", "text", "raw")
_globs = st.lists(st.text(st.sampled_from(NAMES + "*?"), max_size=5), min_size=1, max_size=3)
_source_globs = st.lists(
    st.text(st.sampled_from(SOURCES + "*?"), max_size=5), min_size=1, max_size=2
)


def _key(entry: Entry) -> tuple[object, ...]:
    value = entry.value
    nan = isinstance(value, float) and math.isnan(value)
    return (
        entry.offset,
        entry.key,
        entry.source,
        "nan" if nan else value,
        entry.text,
        entry.lineno,
    )


def _read(path: Path, where: Any, errors: Any) -> tuple[object, ...]:
    """Everything a read gives: rows, exact entries, counts, or the error it raised."""
    rows: list[tuple[object, ...]] = []
    entries: list[tuple[object, ...]] = []
    try:
        with AlogReader(path, errors=errors, block_size=1024) as reader:
            for batch in reader.frames(_COLUMNS, where=where):
                frame = batch.frame.with_columns(pl.col("double").fill_nan(None))
                rows += frame.rows()
                entries += [_key(e) for e in batch.entries()]
            return (rows, entries, reader.scanned, reader.skipped, reader.truncated)
    except FleetlogError as err:
        return ("error", str(err), rows, entries)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    data=st.booleans().flatmap(alog_bytes),
    variables=_globs | st.just([]),
    sources=_source_globs | st.just([]),
    keys=_globs | st.just([]),
    errors=st.sampled_from(["skip", "raise"]),
    workers=st.sampled_from([1, 2]),
)
def test_a_selective_read_gives_what_a_whole_read_gives(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    data: bytes,
    variables: list[str],
    sources: list[str],
    keys: list[str],
    errors: str,
    workers: int,
) -> None:
    # one worker: blocks are parsed in turn, each one's last entry carried to the next (a
    # recorder's process); two: blocks cut where an entry starts, parsed side by side
    monkeypatch.setattr(alogpass, "_WORKERS", workers)
    path = tmp_path / "s.alog"
    path.write_bytes(data)
    selection = Selection(variables, sources, keys=keys)
    whole = _read(path, lambda heads: selection(heads), errors)
    assert _read(path, selection, errors) == whole
    if variables and not sources and not keys and errors == "skip":
        with OracleReader(path, errors="skip") as old:
            want = [
                _key(e)
                for e in old.entries()
                if math.isfinite(e.offset) and any(glob_match(g, e.key) for g in variables)
            ]
        assert whole[1] == want


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.text(st.sampled_from("0123456789.-+eE x"), max_size=18),
            st.text(st.sampled_from("AB_é\t x"), max_size=24),
            st.text(st.sampled_from("p:@é x"), max_size=18),
            st.integers(0, 22),
            st.integers(0, 22),
            st.integers(0, 18),
            st.integers(0, 2),
            st.text(st.sampled_from("v 1."), max_size=4),
        ),
        max_size=30,
    )
)
def test_the_line_tests_are_the_column_rule(
    rows: list[tuple[str, str, str, int, int, int, int, str]],
) -> None:
    lines = [
        f"{t.ljust(wt)}{' ' * gap}{k.ljust(wk)} {s.ljust(ws)} {v}"
        for t, k, s, wt, wk, ws, gap, v in rows
    ]
    frame = pl.DataFrame({"l": lines}, schema={"l": pl.String}).with_row_index("idx")
    # the standard layout as it was first written: each column cut out and matched
    line = pl.col("l")
    source = line.str.slice(37, 16)
    sliced = (
        (source.str.len_chars() == 16)
        & line.str.slice(0, 16).str.contains(r"^-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)? +$")
        & line.str.slice(16, 21).str.contains(r"^[^ ]+ +$")
        & source.str.contains(r"^[^ ]* +$")
    )
    std = frame.select(sliced).to_series()
    assert frame.select(standard_layout(pl)).to_series().to_list() == std.to_list()
    wide = overflow_fields(pl, frame.filter(~std))["idx"].to_list()
    want = [s or i in wide for i, s in enumerate(std.to_list())]
    assert frame.select(entry_line(pl)).to_series().to_list() == want


def test_literals_are_what_every_match_holds() -> None:
    assert glob_literal("NAV_X") == "NAV_X"
    assert glob_literal("a?bc*d") == "bc"
    assert Selection(["NAV_X"]).literals == ("NAV_X",)
    assert Selection(["NAV_*", "*_Y"]).literals == ("NAV_", "_Y")
    assert Selection(["*"]).literals is None  # no text every match holds
    assert Selection(["NAV_X", "?"]).literals is None
    assert Selection(["*"], ["pNav"]).literals == ("pNav",)
    assert Selection(keys=["pHelm*"]).literals == ("pHelm",)
    assert Selection(["\udcffX"]).literals is None  # no text polars can search
    assert Selection().literals is None


@pytest.mark.parametrize("continued", [False, True])
def test_a_block_with_and_without_continuation_lines(tmp_path: Path, continued: bool) -> None:
    lines = [
        "1.00000         NAV_X                pNav            1.00000      ",
        "2.00000         NAV_Y                pHelmIvP:HELM_VAR_INIT x=1 ",
        "2.50000         DEPLOY               pHelmIvP        true ",
        "3.00000         NAV_X                pNav            3.00000      ",
    ]
    if continued:
        lines.insert(3, "12 looks like an entry, continues DEPLOY ")
    path = tmp_path / "b.alog"
    path.write_text("\n".join(lines) + "\n")
    selection = Selection(["NAV_X"])
    with AlogReader(path, errors="skip") as reader:
        got = [(e.lineno, e.text) for e in reader.entries(where=selection)]
        assert got == [(1, "1.00000"), (4 + continued, "3.00000")]
        assert reader.scanned == 4
