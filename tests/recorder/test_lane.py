"""The fast lane writes and counts exactly what the general way does (recorder/lane.py).

Real Zenoh samples (loopback), two recorders with the same fake clock: one logs through
``SampleDecoder.decode`` + ``Recorder.handle``, the other through ``Lane.pump``. Their files,
counters and posts must be identical, and the lane must have taken the common samples.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from lane_support import PREFIX, T0, Part, SampleTap, both_ways, mission, sample_tap

import fleetlog.recorder.lane as lane_module
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.lane import Lane
from fleetlog.transport.bus import SampleDecoder
from fleetlog.wire.message import encode_attachment

DOUBLE = "text/plain;moos-double"
STRING = "text/plain;moos-string"
BINARY = "application/octet-stream"


@pytest.fixture(scope="module")
def tap() -> Iterator[SampleTap]:
    with sample_tap() as made:
        yield made


def att(when: float, source: str = "pNav", aux: str = "", community: str = "V") -> bytes:
    return encode_attachment(when, source, aux, community, None)


def doubles(name: str, n: int, source: str = "pNav", start: float = T0 + 1) -> list[Part]:
    return [
        (PREFIX + name, repr(i * 0.25 - 3).encode(), DOUBLE, att(start + i * 0.01, source))
        for i in range(n)
    ]


def check(tap: SampleTap, parts: list[Part], body: str = "WildcardLogging = true") -> int:
    """Assert both ways wrote and counted the same; return how many the lane took."""
    samples = tap.samples(parts)
    assert len(samples) == len(parts)
    general, lane = both_ways(mission(body), samples, T0 + 2)
    assert general.files["alog"].startswith(b"%%%")
    assert lane.files == general.files
    assert lane.stats == general.stats
    assert lane.posted == general.posted
    return lane.fast


def test_common_traffic_takes_the_lane(tap: SampleTap) -> None:
    parts = doubles("NAV_X", 50) + doubles("NAV_Y", 50, source="pHelm")
    parts += [
        (PREFIX + "NOTE", f"text {i} % done".encode(), STRING, att(T0 + 1.5, "uX", "b"))
        for i in range(20)
    ]
    parts.sort(key=lambda p: p[1])  # interleave the variables
    # The first sample of each variable goes the general way (its type is learned there).
    assert check(tap, parts) == len(parts) - 3
    general, _ = both_ways(mission(), tap.samples(parts), T0 + 2)
    assert general.files["alog"].count(b" pHelm ") == 50


@pytest.mark.parametrize(
    "body", ["MarkDataType = true", "LogAuxSrc = true\nDoublePrecision = 9", "LogFormat = em"]
)
def test_formats_follow_the_configuration(tap: SampleTap, body: str) -> None:
    parts = doubles("A", 5) + [(PREFIX + "B", b"x y", STRING, att(T0 + 1, "s", "aux"))] * 3
    assert check(tap, parts, "WildcardLogging = true\n" + body) == 6


def test_percent_signs_in_names_and_sources(tap: SampleTap) -> None:
    parts = [(PREFIX + "A%25B", b"1.5", DOUBLE, att(T0 + 1, "p%s%d", "%%"))] * 4
    assert check(tap, parts) >= 3


@pytest.mark.parametrize(
    ("label", "odd"),
    [
        ("nan", (PREFIX + "A", b"nan", DOUBLE, att(T0 + 1))),
        ("not a number", (PREFIX + "A", b"1.5x", DOUBLE, att(T0 + 1))),
        ("ahead of the clock", (PREFIX + "A", b"1", DOUBLE, att(T0 + 9))),
        ("before LOGSTART", (PREFIX + "A", b"1", DOUBLE, att(T0 - 1))),
        ("time not finite", (PREFIX + "A", b"1", DOUBLE, att(float("inf")))),
        ("no attachment", (PREFIX + "A", b"1", DOUBLE, None)),
        ("cut attachment", (PREFIX + "A", b"1", DOUBLE, att(T0 + 1)[:-1])),
        ("replay time", (PREFIX + "A", b"1", DOUBLE, encode_attachment(T0 + 1, "p", "", "V", 5.0))),
        ("escaped source", (PREFIX + "A", b"1", DOUBLE, att(T0 + 1, "p\nq"))),
        ("other community", (PREFIX + "A", b"1", DOUBLE, att(T0 + 1, community="W"))),
        ("type clash", (PREFIX + "A", b"text", STRING, att(T0 + 1))),
        ("binary", (PREFIX + "A", b"\x00\x01", BINARY, att(T0 + 1))),
        ("escaped key", (PREFIX + "A%0A", b"1", DOUBLE, att(T0 + 1))),
        ("unreadable key", (PREFIX + "%G0", b"1", DOUBLE, att(T0 + 1))),
        ("command", (PREFIX + "PLOGGER_CMD", b"NOTE=hello", STRING, att(T0 + 1))),
        ("system variable", (PREFIX + "MOOS_DEBUG", b"note", STRING, att(T0 + 1))),
    ],
)
def test_odd_samples_go_the_general_way(tap: SampleTap, label: str, odd: Part) -> None:
    # Plain samples around the odd one; the odd one repeated, so a wrong cache would show.
    parts = [*doubles("A", 3), odd, *doubles("A", 3, start=T0 + 1.2), odd]
    assert check(tap, parts) >= 4, label


@pytest.mark.parametrize(
    "body",
    [
        "WildcardLogging = false\nLog = A @ 0.5",
        "WildcardOmitPattern = A\nWildcardExclusionLog = true",
        "SyncLog = true @ 0.2\nLog = A @ 0",
        "StartPaused = true",
    ],
)
def test_configurations_the_lane_leaves_alone(tap: SampleTap, body: str) -> None:
    parts = doubles("A", 10)
    check(tap, parts, body)


def test_strings_with_newlines_and_not_utf8(tap: SampleTap) -> None:
    parts = [
        (PREFIX + "S", b"plain", STRING, att(T0 + 1)),
        (PREFIX + "S", b"a\nb", STRING, att(T0 + 1)),
        (PREFIX + "S", b"a\n12 b", STRING, att(T0 + 1)),
        (PREFIX + "S", b"\xff\xfe", STRING, att(T0 + 1)),
        (PREFIX + "S", b"", STRING, att(T0 + 1)),
        (PREFIX + "S", b"  1.5  ", STRING, att(T0 + 1)),
    ]
    # Fast: the last two (the first sample and the three odd ones go the general way).
    assert check(tap, parts) == 2


def test_a_flood_of_origins_keeps_the_caches_bounded(
    tap: SampleTap, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # Two keys of eight origins each would hold 16 formats: the bound of 10 must act.
    monkeypatch.setattr(lane_module, "_MAX_TAILS", 8)
    monkeypatch.setattr(lane_module, "_MAX_FORMATS", 10)
    parts = [(PREFIX + f"K{i % 2}", b"1.5", DOUBLE, att(T0 + 1, f"p{i % 23}")) for i in range(300)]
    samples = tap.samples(parts)
    general, lane = both_ways(mission(), samples, T0 + 2)
    assert lane.files == general.files
    assert lane.stats == general.stats
    assert lane.fast > 0
    # The same samples through one lane: its caches never pass their bounds.
    rec = Recorder(mission(), vehicle="V", publish=lambda m: None, cwd=tmp_path, clock=lambda: T0)
    rec.start()
    way = Lane(rec, SampleDecoder(PREFIX), lambda info, sample: None)
    for sample in samples:
        way.pump(sample, lambda: None, 1)
        assert way.cached == sum(len(plan.formats) for plan in way._plans.values()) <= 10
    rec.stop()
