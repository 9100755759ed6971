"""Fuzzing the MOOS protocol decoder: bytes from a MOOSDB (or anything on its port) are hostile.

Whatever the bytes, decoding raises only :class:`FormatError` and never holds more than the
packet limit; whatever the messages, encoding then decoding gives them back. The short runs
are in the normal suite; ``python -m pytest -m slow tests/moos/test_protocol_fuzz.py`` runs
100,000 cases of each.
"""

from __future__ import annotations

import contextlib
import struct

import pytest
from helpers import REFERENCE
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.protocol import Message, PacketReader, decode_packet, encode_packet

LIMIT = 1 << 16
BUDGETS = [pytest.param(200, id="short"), pytest.param(100_000, id="full", marks=pytest.mark.slow)]

_REAL = (REFERENCE / "moos-wire" / "conn2.client-to-db.bin").read_bytes()[32:]

_text = st.text(max_size=12) | st.sampled_from(["", "NAV_X", "\udcff\x00", "#1"])
_messages = st.builds(
    Message,
    msg_type=st.sampled_from("NRU*/~CA.iKWQT^"),
    data_type=st.sampled_from("DSB"),
    key=_text,
    time=st.floats(allow_nan=False) | st.just(1.7e9),
    double=st.floats(allow_nan=False),
    string=st.binary(max_size=64),
    source=_text,
    aux=_text,
    community=_text,
    double2=st.floats(allow_nan=False),
    id=st.integers(-(2**31), 2**31 - 1),
)


def _mutated(data: st.DataObject) -> bytes:
    """A real packet stream with bytes flipped, lengths rewritten, pieces cut or repeated."""
    raw = bytearray(_REAL[: data.draw(st.integers(0, len(_REAL)))])
    for _ in range(data.draw(st.integers(0, 4))):
        if not raw:
            break
        pos = data.draw(st.integers(0, len(raw) - 1))
        how = data.draw(st.sampled_from(["byte", "int", "cut", "dup"]))
        if how == "byte":
            raw[pos] = data.draw(st.integers(0, 255))
        elif how == "int" and pos + 4 <= len(raw):
            value = data.draw(st.sampled_from([-1, 0, 1, 9, 54, 2**31 - 1, -(2**31)]))
            raw[pos : pos + 4] = struct.pack("<i", value)
        elif how == "cut":
            del raw[pos:]
        else:
            raw[pos:pos] = raw[pos : pos + data.draw(st.integers(1, 64))]
    return bytes(raw)


def _check_stream(data: bytes, step: int) -> None:
    reader = PacketReader(max_size=LIMIT)
    try:
        for i in range(0, len(data), step):
            for packet in reader.feed(data[i : i + step]):
                assert encode_packet(packet)  # whatever decoded re-encodes
            assert reader.pending <= LIMIT
    except FormatError:
        pass


@pytest.mark.parametrize("cases", BUDGETS)
def test_fuzz_decoder_on_random_and_mutated_streams(cases: int) -> None:
    @settings(
        max_examples=cases, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(st.data())
    def check(data: st.DataObject) -> None:
        raw = data.draw(st.binary(max_size=512)) if data.draw(st.booleans()) else _mutated(data)
        step = data.draw(st.integers(1, 600))
        _check_stream(raw, step)
        with contextlib.suppress(FormatError):
            decode_packet(raw, max_size=LIMIT)

    check()


@pytest.mark.parametrize("cases", BUDGETS)
def test_fuzz_messages_survive_encoding(cases: int) -> None:
    @settings(
        max_examples=cases, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(st.lists(_messages, max_size=5))
    def check(messages: list[Message]) -> None:
        packet = encode_packet(messages)
        assert decode_packet(packet) == messages
        assert PacketReader().feed(packet) == [messages]

    check()
