"""The schedule in runs against the one-record-at-a-time schedule it replaced (the oracle).

Logs written as pLogger writes them, out of order, with ties, duplicates, entries before
LOGSTART, binary values (some unreadable), bytes that are not UTF-8 and several inputs,
read in small blocks and small runs so that windows, runs and blocks cut each other
anywhere: both schedules must give the same entries in the same order, with the same late
marks and the same counts.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from replay_support import Line, write_session
from schedule_oracle import Schedule as Oracle

from fleetlog.moos.alog import BinaryRef
from fleetlog.replayer.inputs import ReplayInput, open_inputs
from fleetlog.replayer.items import KEY, LATE, ORIGIN, PAYLOAD, SOURCE, TIME, VALUE, payload_expr
from fleetlog.replayer.schedule import Schedule
from fleetlog.wire.message import encode_value

#: marks a string value whose bytes are then replaced by ones that are not UTF-8
_BAD = "BADBYTES"

offsets = st.one_of(
    st.sampled_from([-1.0, 0.0, 0.5, 1.0, 1.0, 2.25, 3.0]),
    st.floats(min_value=-0.5, max_value=5.0).map(lambda x: round(x, 3)),
)
values = st.one_of(
    st.sampled_from([1.0, 2.5, -0.0, "a", "a b", "", _BAD, b"\x00\x01", b"blob"]),
    st.floats(allow_nan=False, allow_infinity=False, width=32),
)
lines = st.builds(
    Line,
    offsets,
    st.sampled_from(["NAV_X", "NAV_Y", "DEPLOY", "X"]),
    st.sampled_from(["pNav", "pHelm:aux", "iGPS@beta"]),
    values,
)


@st.composite
def logs(draw: st.DrawFn) -> list[Line]:
    """Lines, some of them repeated later (re-deliveries)."""
    out = draw(st.lists(lines, max_size=40))
    for _ in range(draw(st.integers(0, 6))):
        if out:
            out.insert(draw(st.integers(0, len(out))), out[draw(st.integers(0, len(out) - 1))])
    return out


def _write(base: Path, index: int, entries: Sequence[Line], vehicle: str) -> Path:
    session = write_session(
        base / f"in{index}", entries, vehicle=vehicle, root=f"LOG_{index}_1_1_2027_____00_00_00"
    )
    alog = next(session.glob("*.alog"))
    data = alog.read_bytes()
    if _BAD.encode() in data:
        alog.write_bytes(data.replace(_BAD.encode(), b"b\xffd", 1))
    blog = next(session.glob("*.blog"))
    if len(blog.read_bytes()) > 40:
        # a blog cut short: the last payloads are unreadable, which both must count alike
        blog.write_bytes(blog.read_bytes()[:-3])
    return session


def _plan(items: Iterable[Any]) -> list[tuple[object, ...]]:
    """What a schedule plays: time, input, name, source, value, late, a binary's bytes."""
    out: list[tuple[object, ...]] = []
    for item in items:
        if isinstance(item, tuple) and not hasattr(item, "entry"):  # the schedule in runs
            fields = (TIME, ORIGIN, KEY, SOURCE, VALUE, LATE)
            binary = isinstance(item[VALUE], BinaryRef)  # the others' payloads come early
            out.append((*(item[i] for i in fields), item[PAYLOAD] if binary else None))
        else:  # the oracle's Item(time, origin, entry, late, payload)
            entry = item.entry
            out.append(
                (
                    item.time,
                    item.origin,
                    entry.key,
                    entry.source,
                    entry.value,
                    item.late,
                    item.payload,
                )
            )
    return out


def _both(
    inputs: list[ReplayInput], window: int, dedupe: bool, memory: int, run: int
) -> tuple[object, object]:
    oracle = Oracle(inputs, window=window, dedupe=dedupe, memory=memory)
    try:
        expected = (_plan(oracle), oracle.before_logstart, oracle.duplicates, oracle.late)
    finally:
        oracle.close()
    schedule = Schedule(inputs, window=window, dedupe=dedupe, memory=memory, run=run)
    try:
        got = (_plan(schedule), schedule.before_logstart, schedule.duplicates, schedule.late)
    finally:
        schedule.close()
    return got, expected


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    st.lists(logs(), min_size=1, max_size=3),
    st.sampled_from([0, 1, 2, 5, 10_000]),
    st.booleans(),
    st.sampled_from([1, 3, 65_536]),
    st.sampled_from([1, 2, 7, 1024]),
    st.sampled_from(["alpha", "beta"]),
)
def test_runs_play_what_records_played(
    tmp_path_factory: pytest.TempPathFactory,
    contents: list[list[Line]],
    window: int,
    dedupe: bool,
    memory: int,
    run: int,
    second: str,
) -> None:
    base = tmp_path_factory.mktemp("logs")
    paths = [
        _write(base, i, lines, "alpha" if i == 0 else second) for i, lines in enumerate(contents)
    ]
    # 1 KiB blocks: a log of a few dozen lines is read in several batches
    inputs = open_inputs(paths, block_size=1024)
    try:
        got, expected = _both(inputs, window, dedupe, memory, run)
    finally:
        for item in inputs:
            item.close()
    assert got == expected


def test_a_long_log_in_runs(tmp_path: Path) -> None:
    """Thousands of entries, mostly in order with displaced ones: the one-step passes."""
    entries = [Line(1.0 + i * 0.01, f"V{i % 7}", "p", float(i)) for i in range(5000)]
    for at in (100, 2000, 4990):
        # 4 s (400 entries) behind its neighbours; the first is before LOGSTART
        entries.insert(at, Line(at * 0.01 - 3.0, "LATE", "q", "x"))
    entries.insert(3000, entries[2900])  # a re-delivery
    inputs = open_inputs([write_session(tmp_path / "s", entries)], block_size=4096)
    try:
        for window in (0, 100, 1000):
            got, expected = _both(inputs, window, True, 65_536, 1024)
            assert got == expected
            assert expected[1:] == (1, 1, 0 if window == 1000 else 2)  # type: ignore[index]
    finally:
        for item in inputs:
            item.close()


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(),
            st.floats(min_value=-1e17, max_value=1e17),
            st.floats(min_value=-1e-3, max_value=1e-3),
            st.sampled_from(
                [0.0, -0.0, 1e-4, -1e-4, 9.999999999999999e-05, 1e16, 9999999999999998.0]
            ),
        ),
        min_size=1,
        max_size=50,
    )
)
def test_payloads_made_with_the_columns_are_what_encode_value_writes(doubles: list[float]) -> None:
    """Where the batch query writes a double's payload, it is encode_value's, byte for byte."""
    import polars as pl

    frame = pl.DataFrame(
        {"double": doubles, "type": ["double"] * len(doubles), "text": [""] * len(doubles)},
        schema={"double": pl.Float64, "type": pl.String, "text": pl.String},
    )
    made = frame.select(payload_expr(pl))["double"].to_list()
    for value, payload in zip(doubles, made, strict=True):
        if payload is not None:
            assert payload == encode_value(value)[1], value
        else:
            # only the doubles Python writes with an exponent (or nan, inf) are left out
            assert value != 0, value
            assert not 1e-4 <= abs(value) < 1e16, value
