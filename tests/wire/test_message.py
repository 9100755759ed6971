"""The sample convention: payloads, encodings and the attachment codec."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from zenoh import ZBytes
from zenoh.ext import z_deserialize, z_serialize

from fleetlog.errors import FormatError
from fleetlog.wire.message import (
    ENCODINGS,
    Kind,
    classify_payload,
    decode_attachment,
    decode_value,
    encode_attachment,
    encode_value,
    kind_of_encoding,
    parse_number,
)

texts = st.text(max_size=300)
times = st.floats(allow_nan=False, allow_infinity=False)


@given(times, texts, texts, texts)
def test_attachment_is_zenoh_ext_tuple(t: float, src: str, aux: str, com: str) -> None:
    data = encode_attachment(t, src, aux, com)
    # Any zenoh-ext implementation must read what fleetlog writes, and the other way round.
    assert z_deserialize(tuple[float, str, str, str], ZBytes(data)) == (t, src, aux, com)
    assert z_serialize((t, src, aux, com)).to_bytes() == data
    meta = decode_attachment(z_serialize((t, src, aux, com)).to_bytes())
    assert (meta.time, meta.source, meta.aux, meta.community) == (t, src, aux, com)
    assert meta.original_time is None


@given(times, texts, texts, texts, times)
def test_attachment_with_original_time(t: float, src: str, aux: str, com: str, o: float) -> None:
    data = encode_attachment(t, src, aux, com, o)
    assert data == z_serialize((t, src, aux, com, o)).to_bytes()
    assert z_deserialize(tuple[float, str, str, str, float], ZBytes(data)) == (t, src, aux, com, o)
    meta = decode_attachment(data)
    assert meta.original_time == o


def test_attachment_decode_is_cached_but_correct() -> None:
    a = decode_attachment(encode_attachment(1.0, "iGPS", "", "alpha"))
    b = decode_attachment(encode_attachment(2.0, "iGPS", "", "alpha"))
    assert (a.time, b.time) == (1.0, 2.0)
    assert b.source == "iGPS"


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "too short"),
        (b"\x00" * 8 + b"\x05ab", "ends inside a string"),
        (b"\x00" * 8 + b"\xff\xff\xff\xff\xff\xff\xff", "string length"),
        (b"\x00" * 8 + b"\x02\xff\xfe\x00\x00", "not UTF-8"),
    ],
)
def test_garbled_attachment(data: bytes, reason: str) -> None:
    with pytest.raises(FormatError, match=reason):
        decode_attachment(data)


@pytest.mark.parametrize(
    ("value", "kind", "payload"),
    [
        (1.5, Kind.DOUBLE, b"1.5"),
        (-0.0, Kind.DOUBLE, b"-0.0"),
        (1e-7, Kind.DOUBLE, b"1e-07"),
        (3, Kind.DOUBLE, b"3.0"),
        ("", Kind.STRING, b""),
        ("a b,c=d\ne", Kind.STRING, b"a b,c=d\ne"),
        (b"\x00\xff", Kind.BINARY, b"\x00\xff"),
    ],
)
def test_encode_value(value: float | str | bytes, kind: Kind, payload: bytes) -> None:
    assert encode_value(value) == (kind, payload)


def test_bool_is_not_a_double() -> None:
    with pytest.raises(TypeError):
        encode_value(True)


@given(st.one_of(st.floats(allow_nan=False), st.text(), st.binary()))
def test_value_round_trip(value: float | str | bytes) -> None:
    kind, payload = encode_value(value)
    got_kind, got, garbled = decode_value(payload, kind_of_encoding(ENCODINGS[kind]))
    assert not garbled
    assert got_kind is kind
    assert got == value or (isinstance(got, float) and math.isnan(got))


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (float("nan"), b"nan"),
        (-float("nan"), b"-nan"),
        (math.copysign(float("nan"), -1.0), b"-nan"),
        (float("-inf"), b"-inf"),
        (-0.0, b"-0.0"),
    ],
)
def test_a_nan_keeps_its_sign_on_the_wire(value: float, text: bytes) -> None:
    assert encode_value(value) == (Kind.DOUBLE, text)
    _, got, garbled = decode_value(text, Kind.DOUBLE)
    assert not garbled
    assert isinstance(got, float)
    assert math.copysign(1.0, got) == math.copysign(1.0, value)
    assert math.isnan(got) == math.isnan(value)


@pytest.mark.parametrize(
    ("encoding", "kind"),
    [
        ("text/plain;moos-double", Kind.DOUBLE),
        ("text/plain;moos-string", Kind.STRING),
        ("application/octet-stream;moos-binary", Kind.BINARY),
        ("text/plain", Kind.STRING),
        ("text/plain;charset=utf-8", Kind.STRING),
        ("zenoh/string", Kind.STRING),
        ("application/octet-stream", Kind.BINARY),
        ("zenoh/bytes", None),
        ("application/json", None),
    ],
)
def test_kind_of_encoding(encoding: str, kind: Kind | None) -> None:
    assert kind_of_encoding(encoding) is kind


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b"12.5", (Kind.DOUBLE, 12.5)),
        (b"-3", (Kind.DOUBLE, -3.0)),
        (b"1e3", (Kind.DOUBLE, 1000.0)),
        (b".5", (Kind.DOUBLE, 0.5)),
        (b"nan", (Kind.STRING, "nan")),
        (b"inf", (Kind.STRING, "inf")),
        (b"1_000", (Kind.STRING, "1_000")),
        (b" 1.5", (Kind.STRING, " 1.5")),
        (b"true", (Kind.STRING, "true")),
        (b"", (Kind.STRING, "")),
        (b"\xff\x00", (Kind.BINARY, b"\xff\x00")),
    ],
)
def test_plain_publisher_payloads(payload: bytes, expected: tuple[Kind, object]) -> None:
    assert classify_payload(payload) == expected


def test_garbled_double_is_kept_as_string() -> None:
    kind, value, garbled = decode_value(b"not a number", Kind.DOUBLE)
    assert (kind, value, garbled) == (Kind.STRING, "not a number", True)
    kind, value, garbled = decode_value(b"\xff", Kind.STRING)
    assert (kind, value, garbled) == (Kind.BINARY, b"\xff", True)


def test_parse_number_rejects_overflow_to_inf() -> None:
    assert parse_number(b"1e999") is None
