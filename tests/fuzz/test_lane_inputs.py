"""Fuzz the recorder's fast lane against the general way (issue 18, recorder/lane.py).

Hostile samples — keys, payloads, encodings, attachments and times a peer controls, mixed
with the plain ones the lane is for, on a few keys and publishers so that its caches are
used — become real Zenoh samples (loopback), which two recorders with the same
configuration and fake clock log: one through the lane, one the general way
(``SampleDecoder.decode`` + ``Recorder.handle``). Every file, counter and post must be the
same: whatever the lane takes it writes exactly as the specification would, and whatever
it cannot it hands on.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from fuzzer import Fuzzer
from hostile import (
    attachments,
    encodings,
    hostile_text,
    key_chunks,
    message_times,
    payloads,
)
from hypothesis import strategies as st
from lane_support import PREFIX, T0, Part, SampleTap, both_ways, mission, sample_tap

from fleetlog.wire.message import ENCODINGS, Kind, encode_attachment


def _mostly(plain: list[str], hostile: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    """Seven times in eight one of ``plain``, else ``hostile``."""
    return st.integers(0, 7).flatmap(lambda n: st.sampled_from(plain) if n else hostile)


#: origins: mostly plain, some hostile
_origins = st.tuples(
    _mostly(["pNav", "pHelm", "", "uX%s"], hostile_text),
    _mostly(["", "", "bhv"], hostile_text),
    _mostly(["V", "V", "W", ""], hostile_text),
)
_DOUBLE = ENCODINGS[Kind.DOUBLE]
_STRING = ENCODINGS[Kind.STRING]


@st.composite
def _plain(
    draw: st.DrawFn, key: str, double: bool, origin: tuple[str, str, str], now: float
) -> Part:
    """A sample the lane is meant for (it may still not be: the value or time may be odd)."""
    if double != (draw(st.integers(0, 7)) == 0):  # now and then not the variable's type
        value = draw(st.floats(allow_nan=True, allow_infinity=True) | st.integers(-9, 9))
        payload, encoding = repr(float(value)).encode(), _DOUBLE
    else:
        text = draw(st.text(max_size=30) | st.sampled_from(["1.5", " 2 ", "a\nb", "%d"]))
        payload, encoding = text.encode("utf-8", "surrogatepass"), _STRING
    odd = draw(st.integers(0, 5))
    when = draw({0: message_times, 1: st.floats(T0 - 1, now + 30)}.get(odd, st.floats(T0, now + 5)))
    return key, payload, encoding, encode_attachment(when, *origin, None)


@st.composite
def _hostile(draw: st.DrawFn, key: str, origin: tuple[str, str, str]) -> Part:
    """A sample whose every part a peer may have crafted."""
    if draw(st.booleans()):
        replay = draw(st.none() | message_times)
        attachment: bytes | None = encode_attachment(draw(message_times), *origin, replay)
    else:
        attachment = draw(st.none() | attachments)
    encoding = draw(st.sampled_from([_DOUBLE, _STRING]) | encodings)
    return key, draw(payloads), encoding, attachment


@st.composite
def lane_cases(draw: st.DrawFn) -> tuple[list[Part], str, float]:
    chunks = _mostly(["NAV_X", "DEPLOY", "NAV_X", "MOOS_DEBUG", "PLOGGER_CMD", "A%25"], key_chunks)
    keys = draw(st.lists(st.tuples(chunks, st.booleans()), min_size=1, max_size=3))
    origins = draw(st.lists(_origins, min_size=1, max_size=3))
    now = T0 + draw(st.floats(0, 20))
    parts = []
    for _ in range(draw(st.integers(1, 16))):
        chunk, double = draw(st.sampled_from(keys))
        key = PREFIX + chunk
        origin = draw(st.sampled_from(origins))
        plain = draw(st.integers(0, 4)) > 0
        parts.append(draw(_plain(key, double, origin, now) if plain else _hostile(key, origin)))
    flags = {
        "MarkDataType": draw(st.booleans()),
        "LogAuxSrc": draw(st.booleans()),
        "MarkExternalCommunityMessages": draw(st.booleans()),
    }
    body = "WildcardLogging = true\n" + "\n".join(
        f"{k} = {'true' if v else 'false'}" for k, v in flags.items()
    )
    body += f"\nDoublePrecision = {draw(st.integers(0, 12))}"
    return parts, body, now


@pytest.fixture(scope="module")
def tap() -> Iterator[SampleTap]:
    with sample_tap() as made:
        yield made


def test_fuzz_lane(fuzz: Fuzzer, tap: SampleTap) -> None:
    def check(case: tuple[list[Any], str, float]) -> None:
        parts, body, now = case
        samples = tap.samples(parts)
        general, lane = both_ways(mission(body), samples, now)
        assert lane.files == general.files
        assert lane.stats == general.stats
        assert lane.posted == general.posted

    fuzz.run(lane_cases(), check)
