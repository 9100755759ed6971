"""The replayer's small parts: commands, keys, rates, timing histogram, clocks, inputs, memory."""

from __future__ import annotations

import gc
import gzip
import json
import threading
import time
import tracemalloc
from pathlib import Path

import pytest
import zstandard
from hypothesis import given, settings
from hypothesis import strategies as st
from replay_support import Line, MakeSession, write_session

from fleetlog.cli.replay_terminal import format_status
from fleetlog.errors import FormatError, ReplayError
from fleetlog.replayer.clock import FakeClock, RealClock
from fleetlog.replayer.control import (
    KeyDecoder,
    Pause,
    Resume,
    Seek,
    SetRate,
    Step,
    Stop,
    Toggle,
    describe,
    next_rate,
    parse_query,
    parse_request,
)
from fleetlog.replayer.engine import Player
from fleetlog.replayer.inputs import open_inputs, parse_remote
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.report import Lateness, State, Status
from fleetlog.storage.alogscan import read_head
from fleetlog.wire.message import MoosMessage

# -- commands


@pytest.mark.parametrize(
    ("params", "command"),
    [
        ({"cmd": "pause"}, Pause()),
        ({"cmd": "resume"}, Resume()),
        ({"cmd": "play"}, Resume()),
        ({"cmd": "toggle"}, Toggle()),
        ({"cmd": "stop"}, Stop()),
        ({"cmd": "seek", "t": "12.5"}, Seek(to=12.5)),
        ({"cmd": "seek", "dt": "-5"}, Seek(by=-5.0)),
        ({"cmd": "rate", "x": "2"}, SetRate(2.0)),
        ({"cmd": "rate", "x": "fast"}, SetRate(None)),
        ({"cmd": "rate", "x": "+"}, SetRate(steps=1)),
        ({"cmd": "rate", "x": "-"}, SetRate(steps=-1)),
        ({"cmd": "step"}, Step(1)),
        ({"cmd": "step", "n": "3"}, Step(3)),
        ({"cmd": "step", "dt": "0.5"}, Step(seconds=0.5)),
        ({"cmd": " PAUSE "}, Pause()),
    ],
)
def test_parse_query(params: dict[str, str], command: object) -> None:
    assert parse_query(params) == command


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({}, "give cmd="),
        ({"cmd": "jump"}, "unknown replay command cmd='jump'"),
        ({"cmd": "seek"}, "exactly one of t="),
        ({"cmd": "seek", "t": "1", "dt": "2"}, "exactly one of t="),
        ({"cmd": "seek", "t": "x"}, "t='x' is not a number"),
        ({"cmd": "seek", "t": "nan"}, "not a finite number"),
        ({"cmd": "rate"}, "cmd=rate needs x="),
        ({"cmd": "rate", "x": "0"}, "outside"),
        ({"cmd": "step", "n": "0"}, "whole number"),
        ({"cmd": "step", "n": "1.5"}, "whole number"),
        ({"cmd": "step", "dt": "-1"}, "more than 0"),
    ],
)
def test_parse_query_refuses(params: dict[str, str], message: str) -> None:
    with pytest.raises(ReplayError, match=message.replace("(", r"\(")):
        parse_query(params)


def test_control_requests_as_json_or_parameters() -> None:
    assert parse_request(None, "cmd=seek;t=5") == ("seek", Seek(5.0))
    assert parse_request(None, "cmd=seek&dt=-5") == ("seek", Seek(by=-5.0))
    assert parse_request(b'{"cmd": "seek", "t": 120}', "") == ("seek", Seek(120.0))
    assert parse_request(b'{"cmd": "rate", "x": "fast"}', "") == ("rate", SetRate(None))
    assert parse_request(b'{"cmd": "step", "n": 3}', "") == ("step", Step(3))
    assert parse_request(b'{"cmd": "status"}', "") == ("status", None)
    for payload, params, match in (
        (None, "", "names no command"),
        (b'{"cmd": "fly"}', "", "unknown command 'fly'"),
        (b'{"cmd": "seek", "t": true}', "", "argument 't' is not a string"),
        (b'{"cmd": "pause", "t": 1}', "", "takes no argument 't'"),
        (None, "cmd=seek", "exactly one of t="),
        (None, "cmd=rate;x=1000", "outside"),
        (b"[1]", "", "not a JSON object"),
        (b"x" * 70000, "", "at most"),
    ):
        with pytest.raises(FormatError, match=match):
            parse_request(payload, params)


def test_control_replies_say_what_was_done() -> None:
    status = {"state": "paused", "offset": 75.5, "end": 120.0, "rate": 2.0}
    assert describe("pause", status) == "paused at 1:15.5 of 2:00.0"
    assert describe("rate", {**status, "state": "playing"}) == "playing at 2.0x at 1:15.5 of 2:00.0"
    assert describe("seek", {**status, "end": None, "rate": "fast"}) == "moved to 1:15.5 (paused)"


def test_keys() -> None:
    keys = KeyDecoder(seek_step=5.0)
    assert keys.feed(b" +-nNqp=_x") == [
        Toggle(),
        SetRate(steps=1),
        SetRate(steps=-1),
        Step(1),
        Step(seconds=1.0),
        Stop(),
        Toggle(),
        SetRate(steps=1),
        SetRate(steps=-1),
    ]
    assert keys.feed(b"\x1b[C\x1b[D\x1bOA\x1b[B") == [
        Seek(by=5.0),
        Seek(by=-5.0),
        Seek(by=50.0),
        Seek(by=-50.0),
    ]
    # An escape sequence split across reads waits for its end.
    assert keys.feed(b"\x1b") == []
    assert keys.feed(b"[") == []
    assert keys.feed(b"C ") == [Seek(by=5.0), Toggle()]
    assert keys.feed(b"\x1b[Z") == []  # unknown sequences are ignored


@pytest.mark.parametrize(
    ("rate", "steps", "expected"),
    [
        (1.0, 1, 2.0),
        (1.0, -1, 0.5),
        (0.1, -1, 0.1),
        (100.0, 1, None),
        (None, -1, 100.0),
        (None, 1, None),
        (3.0, 1, 5.0),
        (3.0, -1, 2.0),
    ],
)
def test_rate_ladder(rate: float | None, steps: int, expected: float | None) -> None:
    assert next_rate(rate, steps) == expected


# -- reports


def test_lateness_percentiles() -> None:
    late = Lateness()
    assert late.percentile(50) is None
    for value in [0.0001] * 98 + [0.0015, 0.25]:
        late.add(value)
    assert late.percentile(50) == pytest.approx(0.00011)
    assert late.percentile(99) == pytest.approx(0.00151)
    assert late.percentile(100) == pytest.approx(0.25)  # past the bins: the maximum
    assert late.count == 100
    late.add(-1.0)  # early counts as on time
    assert late.max == pytest.approx(0.25)


def test_status_line() -> None:
    status = Status(State.PLAYING, 1e9 + 75, 75.0, 0.0, 150.0, 2.0, 12, 3, 0, ("alpha",))
    assert status.fraction == 0.5
    line = format_status(status, width=10)
    assert (
        line == "▶ playing  1:15.000 / 2:30.000 [#####.....]  50.0%  ×2  published 12, filtered 3"
    )
    unknown = Status(State.WAITING, 1e9, 3725.5, 0.0, None, None, 0, 0, 0, ("alpha",))
    assert format_status(unknown) == "⧗ waiting for client  1:02:05.500  fast  published 0"
    assert unknown.to_dict()["rate"] == "fast"
    assert unknown.to_dict()["fraction"] is None


# -- clocks


def test_fake_clock_runs_actions_in_time_order() -> None:
    clock = FakeClock()
    seen: list[float] = []
    clock.call_at(2.0, lambda: seen.append(clock.now()))
    clock.call_at(1.0, lambda: seen.append(clock.now()))
    assert clock.wait(5.0) is True
    assert clock.wait(5.0) is True
    assert clock.wait(5.0) is False
    assert seen == [1.0, 2.0]
    assert clock.now() == 5.0
    with pytest.raises(ReplayError, match="waits forever"):
        clock.wait(None)
    clock.wake()
    assert clock.wait(None) is True


def test_real_clock_waits_precisely_and_wakes() -> None:
    clock = RealClock()
    errors = []
    for _ in range(20):
        deadline = clock.now() + 0.003
        assert clock.wait(deadline) is False
        errors.append(clock.now() - deadline)
    assert min(errors) >= 0
    assert sorted(errors)[10] < 0.001  # the median: spinning lands within a millisecond
    threading.Timer(0.05, clock.wake).start()
    start = time.monotonic()
    assert clock.wait(clock.now() + 5.0) is True
    assert time.monotonic() - start < 2.0


# -- inputs


def test_inputs_find_their_vehicle(make_session: MakeSession) -> None:
    by_db = make_session([Line(1.0, "A", "p", 1.0)], vehicle="alpha", moos_community="other")
    by_moos = make_session([Line(1.0, "A", "p", 1.0)], vehicle=None, moos_community="bravo")
    inputs = open_inputs([by_db, by_moos])
    try:
        assert [(i.vehicle, i.vehicle_from) for i in inputs] == [
            ("alpha", "DB_TIME"),  # DB_TIME first: it names the MOOSDB that logged it
            ("bravo", "._moos"),
        ]
        assert inputs[0].end == pytest.approx(1_800_000_001.0)
    finally:
        for item in inputs:
            item.close()
    named = open_inputs([by_db, by_moos], ["x", "y"])
    assert [i.vehicle for i in named] == ["x", "y"]
    for item in named:
        item.close()
    with pytest.raises(ReplayError, match="nothing to replay"):
        open_inputs([])
    with pytest.raises(ReplayError, match="a remote input, but no way to fetch it"):
        open_inputs(["alpha:latest"])


def test_a_fleetlog_session_without_mission_names_its_vehicle(make_session: MakeSession) -> None:
    # What `fleetlog record` writes with no mission: no DB_TIME, no ._moos, but its status.
    status = "AppErrorFlag=false,Uptime=0,MOOSName=pLogger,Community=charlie,LogAuxSrc=false"
    bare = make_session(
        [Line(0.0, "PLOGGER_STATUS", "pLogger", status), Line(1.0, "A", "p", 1.0)], vehicle=None
    )
    (found,) = open_inputs([bare])
    try:
        assert (found.vehicle, found.vehicle_from) == ("charlie", "status")
    finally:
        found.close()
    head = read_head(next(bare.glob("*.alog")) if bare.is_dir() else bare)
    assert head.community == "charlie"


@pytest.mark.parametrize("suffix", [".gz", ".zst"])
def test_compressed_alogs(make_session: MakeSession, suffix: str) -> None:
    session = make_session([Line(1.0, "A", "p", 1.0), Line(2.0, "B", "p", "two")])
    alog = next(session.glob("*.alog"))
    data = alog.read_bytes()
    packed = gzip.compress(data) if suffix == ".gz" else zstandard.ZstdCompressor().compress(data)
    alog.with_name(alog.name + suffix).write_bytes(packed)
    alog.unlink()
    sent: list[str] = []

    def collect(_vehicle: str, message: MoosMessage) -> None:
        sent.append(message.name)

    for spec in (session, next(session.glob("*.alog*"))):  # the directory, or the file
        (source,) = open_inputs([spec])
        try:
            assert source.vehicle == "alpha"
            assert source.end is None  # compressed: not known without reading it all
            sent.clear()
            Player([source], collect, FakeClock()).run()
            assert [n for n in sent if n != "PLAYBACK_DB_TIME"] == ["DB_TIME", "A", "B"]
        finally:
            source.close()


def test_remote_specs(tmp_path: Path) -> None:
    assert parse_remote("alpha:latest") is not None
    assert parse_remote("alpha:MOOSLog_1_2_2027_____00_00_00") is not None
    assert parse_remote("dir/alpha:latest") is None
    assert parse_remote("plain") is None
    existing = tmp_path / "x:y"
    existing.mkdir()
    assert parse_remote(str(existing)) is None


# -- memory


def _peak(session: Path) -> int:
    # A block smaller than either log: the reader holds a block, whatever the log's size.
    (source,) = open_inputs([session], block_size=16 << 10)
    try:
        player = Player(
            [source],
            lambda _v, _m: None,
            FakeClock(),
            PlayOptions(rate=None, window=200, dedupe_memory=500),
        )
        gc.collect()
        tracemalloc.start()
        try:
            summary = player.run()
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
            assert summary.published > 0
    finally:
        source.close()


def test_memory_does_not_grow_with_the_log(tmp_path: Path) -> None:
    def lines(count: int) -> list[Line]:
        return [Line(1.0 + i * 0.001, f"V{i % 7}", "p", f"value {i} " * 3) for i in range(count)]

    small = write_session(tmp_path / "small", lines(1_000))
    large = write_session(tmp_path / "large", lines(10_000))
    # Ten times the entries, the same peak: what is held is the re-sort window, the
    # duplicate check's memory, a run of entries and the parser's buffers, all bounded;
    # never the file. (Peaks move by ~100 KB from run to run with what the garbage collector
    # has not yet freed; 30 bytes an entry kept would add 270 KB.)
    assert _peak(large) < 1.25 * _peak(small) + 150_000


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner),
    max_leaves=20,
)


@settings(max_examples=300)
@given(
    st.one_of(
        st.none(),
        st.binary(max_size=64),
        st.dictionaries(
            st.sampled_from(["cmd", "t", "dt", "x", "n", "source", "time", "zz"]),
            _json_values | st.sampled_from(["seek", "rate", "step", "pause", "status", "+"]),
        ).map(lambda obj: json.dumps(obj).encode()),
    ),
    st.text(max_size=60),
)
def test_control_request_fuzz(payload: bytes | None, parameters: str) -> None:
    """Whatever a peer sends, the replay's control reads a command or refuses it in words."""
    try:
        cmd, _ = parse_request(payload, parameters)
    except FormatError:
        return
    assert cmd in ("pause", "resume", "play", "toggle", "stop", "seek", "rate", "step", "status")
