"""What the shore reads from vehicles is hostile: status replies, answering servers, listings.

Each reader is fuzzed: whatever bytes arrive, it returns a value or raises FormatError, never
anything else, and what it returns is bounded.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console

from fleetlog.cli.tables import human_duration, part_span, sessions_table
from fleetlog.errors import FormatError
from fleetlog.shore.control import ControlReply
from fleetlog.shore.status import MAX_COMMANDS, MAX_TEXT, VehicleStatus, describe_command
from fleetlog.wire.control import parse_control_request
from fleetlog.wire.grep_lines import decode_grep_lines
from fleetlog.wire.query import (
    LatestInfo,
    SessionInfo,
    sessions_by_server,
    sessions_from_json,
    sessions_to_json,
    split_server,
    with_server,
)
from fleetlog.wire.session_meta import SessionMeta

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=40),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=10), inner),
    max_leaves=30,
)


def test_status_reads_counters_commands_disk_and_clock() -> None:
    reply = {
        "vehicle": "alpha",
        "directory": "./MOOSLog_1_2_2025_____10_00_00",
        "logged": 10,
        "lost": 2,
        "skewed": -1,  # not a count: left out
        "garbled": True,  # not a count either
        "last_error": "x" * 5000,
        "commands": [
            {"time": 1.5, "via": "PLOGGER_CMD", "source": "u", "cmd": "restart", "text": ""}
            | {"ok": True, "did": "new dir", "why": None},
            {"time": 2, "via": "control", "source": "", "cmd": "pause", "text": "PAUSE"}
            | {"ok": False, "did": "", "why": "already paused"},
            {"cmd": "pause"},  # garbled: left out
            "garbage",
        ],
        "disk": {"free": 1 << 30, "total": 1 << 32},
        "clock": {"synchronized": False},
    }
    found = VehicleStatus.from_json(json.dumps(reply).encode(), "abc")
    assert found.session == "MOOSLog_1_2_2025_____10_00_00"
    assert found.counters["logged"] == 10
    assert found.losses == 2
    assert "skewed" not in found.counters
    assert "garbled" not in found.counters
    assert len(found.last_error) == MAX_TEXT
    assert [describe_command(c) for c in found.commands] == [
        "restart: new dir",
        "PAUSE: refused: already paused",
    ]
    assert (found.disk_free, found.disk_total) == (1 << 30, 1 << 32)
    assert found.clock_synchronized is False
    assert found.server == "abc"


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"", "not JSON"),
        (b"[1]", "not a JSON object"),
        (b'{"logged": 1}', "names no vehicle"),
        (b"[" * 100_000, "not JSON"),
        (b" " * (2 << 20), "at most"),
    ],
)
def test_status_refusals(data: bytes, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        VehicleStatus.from_json(data)


@settings(max_examples=300)
@given(st.dictionaries(st.text(max_size=12), json_values, max_size=12), st.binary(max_size=64))
def test_status_fuzz(obj: dict[str, object], noise: bytes) -> None:
    for data in (json.dumps(obj).encode(), noise):
        try:
            found = VehicleStatus.from_json(data)
        except FormatError:
            continue
        assert len(found.commands) <= MAX_COMMANDS
        assert all(isinstance(v, int) and v >= 0 for v in found.counters.values())


def test_status_keeps_only_the_last_commands() -> None:
    entry = {"time": 1, "via": "control", "source": "", "text": "", "did": "", "why": None}
    ring = [{**entry, "cmd": f"c{i}", "ok": True} for i in range(500)]
    found = VehicleStatus.from_json(json.dumps({"vehicle": "a", "commands": ring}).encode())
    assert len(found.commands) == MAX_COMMANDS
    assert found.commands[-1].cmd == "c499"


def test_server_parameter() -> None:
    assert split_server("") == (None, "")
    assert split_server("offset=0;length=10") == (None, "offset=0;length=10")
    assert split_server("offset=0;server=ab12;sha256=1") == ("ab12", "offset=0;sha256=1")
    assert split_server(with_server("brief=1", "ff")) == ("ff", "brief=1")
    assert with_server("", None) == ""
    for bad, match in (
        ("server=XYZ", "Zenoh id"),
        ("server=", "Zenoh id"),
        ("brief=1;server", "Zenoh id"),
        ("server=a;server=b", "twice"),
        ("server=" + "a" * 40, "Zenoh id"),
        ("x" * 9000, "at most"),
    ):
        with pytest.raises(FormatError, match=match):
            split_server(bad)


@settings(max_examples=300)
@given(st.text(max_size=200))
def test_server_parameter_fuzz(text: str) -> None:
    try:
        server, rest = split_server(text)
    except FormatError:
        return
    assert server is None or (len(server) <= 32 and server == server.lower())
    assert not any(item.partition("=")[0] == "server" for item in rest.split(";"))


def test_sessions_of_two_servers_are_kept_apart() -> None:
    one = SessionInfo("S1", (), True)
    two = SessionInfo("S2", (), False)
    left = sessions_to_json("alpha", [one], server="aa", recorder="aa")
    right = sessions_to_json("alpha", [two], server="bb", recorder=None)
    mixed = [left[0], right[0]]
    assert sessions_by_server(mixed) == {"aa": [one], "bb": [two]}
    with pytest.raises(FormatError, match="from 2 processes"):
        sessions_from_json(mixed)
    assert sessions_from_json(left) == [one]
    unfinished = json.dumps({"vehicle": "a", "server": "cc", "sessions": [], "more": True})
    with pytest.raises(FormatError, match="ended before the last one"):
        sessions_by_server([*left, unfinished.encode()])


@settings(max_examples=200)
@given(st.lists(st.binary(max_size=80) | json_values.map(lambda v: json.dumps(v).encode())))
def test_sessions_by_server_fuzz(replies: list[bytes]) -> None:
    with contextlib.suppress(FormatError):
        sessions_by_server(replies)


def test_latest_names_its_server_and_recorder() -> None:
    info = LatestInfo("alpha", "S", True, "recorder", server="aa", recorder="aa")
    assert LatestInfo.from_json(info.to_json()) == info
    served = LatestInfo("alpha", "S", False, "newest", server="bb")
    assert LatestInfo.from_json(served.to_json()).recorder is None


session_objects = st.fixed_dictionaries(
    {
        "name": st.just("MOOSLog_1_2_2025_____10_00_00"),
        "complete": st.booleans(),
        "files": st.just([]),
    },
    optional={
        key: st.none() | st.floats() | st.integers(min_value=-(10**400), max_value=10**400)
        for key in ("start", "duration", "opened")
    }
    | {"part": st.none() | st.integers(min_value=-3, max_value=10**30)},
)


@settings(max_examples=300)
@given(st.lists(session_objects, max_size=4))
def test_a_hostile_listing_is_shown_not_crashed_on(objects: list[dict[str, object]]) -> None:
    # NaN, inf and integers beyond a float are valid JSON to Python's parser: a vehicle can
    # send them, and `fleetlog sessions` must still print its table.
    infos = []
    for obj in objects:
        try:
            infos.append(SessionInfo.from_json(json.loads(json.dumps(obj))))
        except FormatError:
            continue
    for info in infos:
        for value in (info.start, info.duration, info.opened):
            assert value is None or math.isfinite(value)
    out = io.StringIO()
    Console(file=out, width=200).print(sessions_table(infos, None))
    assert out.getvalue().count("MOOSLog_") == len(infos)


def test_a_split_part_is_shown_from_when_it_opened() -> None:
    # Part 2 keeps the mission's LOGSTART (1000): its last entry at 700 s is 1700 in all.
    part = SessionInfo("S2", (), True, start=1000.0, duration=700.0, part=2, opened=1600.0)
    assert part_span(part) == (1600.0, 100.0)
    first = SessionInfo("S1", (), True, start=1000.0, duration=600.0, part=1, opened=1000.2)
    assert part_span(first) == (1000.0, 600.0)  # part 1 is pLogger's LOGSTART, as before
    assert part_span(SessionInfo("S", (), True, start=1000.0, duration=5.0)) == (1000.0, 5.0)
    out = io.StringIO()
    Console(file=out, width=200).print(sessions_table([first, part], "S2"))
    assert "0:01:40" in out.getvalue()  # part 2 ran 100 s, not 700
    assert SessionInfo.from_json(part.as_json()) == part
    assert human_duration(float("nan")) == "-"
    assert human_duration(1e300) == "-"
    assert human_duration(-5.0) == "0:00:00"


def _readers() -> list[tuple[str, Callable[[bytes], object]]]:
    return [
        ("latest", LatestInfo.from_json),
        ("sessions", lambda b: sessions_by_server([b])),
        ("status", lambda b: VehicleStatus.from_json(b, "aa")),
        ("control reply", lambda b: ControlReply.from_json(b, "aa")),
        ("control request", lambda b: parse_control_request(b, "")),
        ("grep", decode_grep_lines),
        ("session metadata", SessionMeta.from_bytes),
    ]


def _read_by_every_reader(payload: bytes) -> None:
    """Each reader returns or raises FormatError: anything else is a crash the peer caused."""
    for name, read in _readers():
        try:
            read(payload)
        except FormatError:
            pass
        except Exception as err:
            pytest.fail(f"{name} reader raised {type(err).__name__}: {err}")


_CRAFTED = [
    b"[" * 200_000 + b"]" * 200_000,  # the parser recursed per level: RecursionError
    b'{"a":' * 100_000 + b"1" + b"}" * 100_000,
    b'{"vehicle":"a","session":"S","writing":true,"how":"recorder","start":1' + b"0" * 400 + b"}",
    b'{"vehicle":"a","directory":"./S","logged":1' + b"0" * 400 + b"}",
    b'{"ok":true,"cmd":"x","did":"","time":1' + b"0" * 400 + b"}",
    b"[1" + b"0" * 400 + b',"K","s","d","1",1]',
]


@pytest.mark.parametrize("payload", _CRAFTED, ids=range(len(_CRAFTED)))
def test_every_reader_refuses_crafted_json_cleanly(payload: bytes) -> None:
    # Valid JSON to Python's parser, and each crashed a reader (RecursionError, or the
    # OverflowError of float(10**400)) before parse_json bounded them at the boundary.
    _read_by_every_reader(payload)


@settings(max_examples=300)
@given(
    st.recursive(
        st.none()
        | st.booleans()
        | st.integers(min_value=-(10**400), max_value=10**400)
        | st.floats()
        | st.text(max_size=20),
        lambda inner: (
            st.lists(inner, max_size=6)
            | st.dictionaries(
                st.sampled_from(["start", "logged", "time", "ok", "cmd", "vehicle", "files", "x"]),
                inner,
            )
        ),
        max_leaves=40,
    )
)
def test_every_reader_takes_any_json_with_huge_numbers(obj: object) -> None:
    payload = json.dumps(obj).encode()
    _read_by_every_reader(payload)
