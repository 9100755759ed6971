"""The recorder's fast paths build exactly what the plain constructors build."""

from __future__ import annotations

import dataclasses
import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.grep_lines import (
    GrepEnd,
    GrepHeader,
    GrepRecord,
    _decode_lines,
    _records,
    decode_grep_lines,
    encode_grep_line,
)
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


# A grep reply: the record lines a vehicle writes are parsed in one call (grep_lines._records);
# every reply, hostile or not, must read as reading it line by line reads it.

_any_records = st.builds(
    GrepRecord,
    st.floats() | st.integers(-(10**20), 10**20),
    texts,
    texts,
    st.sampled_from("dsb"),
    texts,
    st.integers(-(10**20), 10**20),
)
_mangles = st.sampled_from(
    [
        b"",
        b"\n",
        b"\r",
        b" ",
        b"\xff",
        b"\xc3",
        b"\x00",
        b",",
        b"]",
        b"[",
        b'"',
        b"\\",
        b"}",
        b"NaN",
        b"1" * 25,
        b"[1,2],[3]",
        b'{"end":true}',
        b'[1,"a","b","d","t",1],[2,"a","b","d","t",2]',
    ]
)


def _line_by_line(data: bytes) -> object:
    try:
        return _decode_lines(data)
    except FormatError as err:
        return ("refused", str(err))


def _at_once(data: bytes) -> object:
    try:
        return decode_grep_lines(data)
    except FormatError as err:
        return ("refused", str(err))


@settings(max_examples=400, deadline=None)
@given(
    st.lists(_any_records, max_size=8),
    st.booleans(),
    st.booleans(),
    st.lists(st.tuples(st.integers(0, 10_000), _mangles), max_size=3),
)
def test_a_grep_reply_reads_as_line_by_line(
    records: list[GrepRecord],
    header: bool,
    end: bool,
    mangles: list[tuple[int, bytes]],
) -> None:
    items: list[GrepHeader | GrepRecord | GrepEnd] = list(records)
    if header:
        items.insert(0, GrepHeader("S", "S.alog", 1.5, ("%% x",)))
    if end:
        items.append(GrepEnd(len(records), 9, False))
    data = b"".join(encode_grep_line(item) for item in items)
    for at, text in mangles:
        at %= len(data) + 1
        data = data[:at] + text + data[at:]
    assert _at_once(data) == _line_by_line(data)


@given(
    st.lists(
        st.builds(
            GrepRecord,
            st.floats(allow_nan=False, allow_infinity=False),
            texts,
            texts,
            st.sampled_from("dsb"),
            texts,
            st.integers(0, 10**17),
        ),
        max_size=8,
    )
)
def test_what_a_vehicle_writes_is_read_in_one_call(records: list[GrepRecord]) -> None:
    data = b"".join(encode_grep_line(r) for r in records)
    assert _records(data) == records
    end = encode_grep_line(GrepEnd(len(records), 9, False))
    assert decode_grep_lines(data + end) == [*records, GrepEnd(len(records), 9, False)]
