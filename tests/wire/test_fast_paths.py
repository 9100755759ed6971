"""The recorder's fast paths build exactly what the plain constructors build."""

from __future__ import annotations

import dataclasses
import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.message import (
    MoosMessage,
    attachment_fields,
    decode_attachment,
    encode_attachment,
    encode_value,
    new_message,
)

texts = st.text(max_size=40)
times = st.floats(allow_nan=False, allow_infinity=False)
values = st.one_of(st.floats(allow_nan=False), texts, st.binary(max_size=40))


@given(texts, values, times, texts, texts, texts, st.one_of(st.none(), times))
def test_new_message_is_the_dataclass(
    name: str, value: object, t: float, src: str, aux: str, com: str, orig: float | None
) -> None:
    fast = new_message(name, value, t, src, aux, com, orig)  # type: ignore[arg-type]
    slow = MoosMessage(name, value, t, src, aux, com, orig)  # type: ignore[arg-type]
    assert type(fast) is MoosMessage
    assert fast == slow
    assert hash(fast) == hash(slow)
    assert repr(fast) == repr(slow)
    assert pickle.loads(pickle.dumps(fast)) == slow


def test_new_message_stays_frozen() -> None:
    msg = new_message("X", 1.0, 2.0, "src", "", "v", None)
    with pytest.raises(dataclasses.FrozenInstanceError):
        msg.name = "Y"  # type: ignore[misc]


@given(times, texts, texts, texts, st.one_of(st.none(), times))
def test_attachment_fields_match_decode_attachment(
    t: float, src: str, aux: str, com: str, orig: float | None
) -> None:
    data = encode_attachment(t, src, aux, com, orig)
    meta = decode_attachment(data)
    assert attachment_fields(data) == (meta.time, meta.source, meta.aux, meta.community, orig)
    # Twice: the second decode comes from the tail cache.
    assert attachment_fields(data) == (t, src, aux, com, orig)


def test_encode_attachment_tail_cache_keeps_the_time() -> None:
    a = encode_attachment(1.0, "iGPS", "", "alpha")
    b = encode_attachment(2.0, "iGPS", "", "alpha")
    assert a[8:] == b[8:]
    assert attachment_fields(a)[0] == 1.0
    assert attachment_fields(b)[0] == 2.0


def test_attachment_fields_rejects_what_decode_attachment_rejects() -> None:
    with pytest.raises(FormatError, match="too short"):
        attachment_fields(b"\x00" * 10)


@pytest.mark.parametrize("value", [1.5, -0.0, 3, 2**70, float("inf")])
def test_encode_value_fast_double(value: float) -> None:
    assert encode_value(value) == encode_value(float(value))
    assert encode_value(value)[1] == repr(float(value)).encode()
