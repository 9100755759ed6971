"""What the shore reads from vehicles is hostile: status replies, answering servers, listings.

Each reader is fuzzed: whatever bytes arrive, it returns a value or raises FormatError, never
anything else, and what it returns is bounded.
"""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.shore.status import MAX_COMMANDS, MAX_TEXT, VehicleStatus, describe_command
from fleetlog.wire.query import (
    LatestInfo,
    SessionInfo,
    sessions_by_server,
    sessions_from_json,
    sessions_to_json,
    split_server,
    with_server,
)

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
