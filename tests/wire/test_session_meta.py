"""The session metadata schema and the PLOGGER_GAP entry text (docs/wire.md, docs/compat.md)."""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.session_meta import CUT, MAX_META_BYTES, Gap, SessionMeta

META = SessionMeta(
    state="open",
    vehicle="alpha",
    session="LOG_ALPHA_1_1_2027_____00_00_00",
    recorder="a1b2",
    fleetlog="0.1.0",
    opened=1_800_000_000.5,
    logstart=1_800_000_000.25,
    updated=1_800_000_002.0,
    mission_id="m1",
    counters={"logged": 10, "lost": 2},
    gaps=(Gap(1_800_000_001.0, "disk-full", 2, 1_800_000_000.75, 1_800_000_001.0, {"A": 2}),),
    clock={"synchronized": False, "source": "adjtimex"},
    notes={"site": "bay"},
    tags=("trial",),
    host="boat",
    pid=42,
    boot="b00t",
)


def test_round_trip_and_field_order() -> None:
    data = META.to_bytes()
    assert data.endswith(b"\n")
    assert SessionMeta.from_bytes(data) == META
    keys = list(json.loads(data))
    assert keys[:4] == ["format", "state", "vehicle", "session"]
    cut = META.with_state(CUT, 1_800_000_009.0)
    assert (cut.state, cut.closed, cut.updated) == (CUT, 1_800_000_009.0, META.updated)
    assert SessionMeta.from_bytes(cut.to_bytes()) == cut


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"[]", "not a JSON object"),
        (b"{", "not JSON"),
        (b'{"format": 2, "state": "open"}', "format 2"),
        (b'{"format": 1, "state": "paused"}', "state 'paused'"),
        (b'{"format": 1, "state": "open", "opened": "x", "logstart": 1}', "'opened'"),
        (
            b'{"format": 1, "state": "open", "opened": 1, "logstart": 1, "counters": {"a": true}}',
            "counters",
        ),
        (b'{"format": 1, "state": "open", "opened": 1, "logstart": 1, "gaps": [1]}', "gap"),
        (b" " * (MAX_META_BYTES + 1), "at most"),
    ],
)
def test_bad_files_are_refused(data: bytes, message: str) -> None:
    with pytest.raises(FormatError, match=message):
        SessionMeta.from_bytes(data)


@given(st.binary(max_size=512))
def test_any_bytes_give_metadata_or_a_format_error(data: bytes) -> None:
    with contextlib.suppress(FormatError):
        SessionMeta.from_bytes(data)


def test_gap_entry_text_is_moos_pairs() -> None:
    gap = Gap(5.0, "disk-full", 120, 1.25, 3.5, {"NAV_X": 60, "NAV_Y": 60, "A,B": 1})
    assert gap.moos_text() == "reason=disk-full,lost=120,from=1.250,to=3.500,vars=NAV_X:60;NAV_Y:60"
    crash = Gap(9.0, "crash", None, 1.0, 8.0, {}, "LOG_X")
    assert crash.moos_text() == "reason=crash,lost=?,from=1.000,to=8.000,session=LOG_X"
    assert Gap.from_json(gap.as_json()) == gap
