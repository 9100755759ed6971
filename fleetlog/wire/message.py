"""MOOS messages on Zenoh: payload, encoding and attachment (docs/wire.md).

* The payload is the value: UTF-8 text for strings, the decimal text of the number for doubles
  (Python's shortest round-trip ``repr``; a NaN keeps its sign: ``-nan``), raw bytes for binary.
* The encoding says which of the three it is (:data:`ENCODINGS`). A sample with any other
  encoding (a plain Zenoh publisher) is classified by its payload: a number → double, other
  UTF-8 text → string, anything else → binary.
* The attachment is the zenoh-ext serialization of the tuple
  ``(time: f64, source: str, aux: str, community: str[, original_time: f64])``: the
  publisher's MOOS message time (seconds since the epoch), the source process, its aux
  source, the originating community, and, for replayed samples, the original absolute time.
  Any zenoh-ext implementation (Rust, C, C++, Python) decodes it; this module decodes it by
  hand because the recorder does so for every sample.
"""

from __future__ import annotations

import enum
import math
import re
import struct
from dataclasses import dataclass

from fleetlog.errors import FormatError

__all__ = [
    "ENCODINGS",
    "TIME_FIELD",
    "Kind",
    "Meta",
    "MoosMessage",
    "attachment_fields",
    "attachment_tail",
    "classify_payload",
    "decode_attachment",
    "decode_value",
    "encode_attachment",
    "encode_value",
    "kind_of_encoding",
    "new_message",
    "parse_number",
]


class Kind(enum.IntEnum):
    """The three MOOS value types."""

    DOUBLE = 0
    STRING = 1
    BINARY = 2


#: the encoding fleetlog publishes for each kind
ENCODINGS: dict[Kind, str] = {
    Kind.DOUBLE: "text/plain;moos-double",
    Kind.STRING: "text/plain;moos-string",
    Kind.BINARY: "application/octet-stream;moos-binary",
}

_KIND_BY_ENCODING: dict[str, Kind | None] = {v: k for k, v in ENCODINGS.items()}
_NUMBER_RE = re.compile(rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_F64 = struct.Struct("<d")


def kind_of_encoding(encoding: str) -> Kind | None:
    """Return the kind an encoding string declares, or None when the payload must decide.

    ``text/plain`` and ``zenoh/string`` declare strings, ``application/octet-stream`` binary;
    fleetlog's own encodings declare their kind; anything else (``zenoh/bytes``, the default
    of a plain publisher) leaves it to :func:`classify_payload`.
    """
    try:
        return _KIND_BY_ENCODING[encoding]
    except KeyError:
        pass
    base = encoding.split(";", 1)[0]
    kind: Kind | None
    if base in ("text/plain", "zenoh/string"):
        kind = Kind.STRING
    elif base == "application/octet-stream":
        kind = Kind.BINARY
    else:
        kind = None
    if len(_KIND_BY_ENCODING) < 1024:
        _KIND_BY_ENCODING[encoding] = kind
    return kind


def parse_number(text: bytes) -> float | None:
    """Return the double a payload spells (uPokeDB's rule, without nan/inf), else None."""
    if _NUMBER_RE.fullmatch(text) is None:
        return None
    value = float(text)
    return None if math.isinf(value) else value


def classify_payload(payload: bytes) -> tuple[Kind, float | str | bytes]:
    """Classify a payload that came without a fleetlog encoding."""
    number = parse_number(payload)
    if number is not None:
        return Kind.DOUBLE, number
    try:
        return Kind.STRING, payload.decode("utf-8")
    except UnicodeDecodeError:
        return Kind.BINARY, payload


def decode_value(payload: bytes, kind: Kind | None) -> tuple[Kind, float | str | bytes, bool]:
    """Turn a payload into a value of the declared kind.

    Returns:
        ``(kind, value, garbled)``: ``garbled`` is True when the payload did not fit its
        declared kind (a "double" that is not a number, a "string" that is not UTF-8); the
        value is then kept as what it is (string or binary) so nothing is lost.
    """
    if kind is None:
        found, value = classify_payload(payload)
        return found, value, False
    if kind is Kind.DOUBLE:
        try:
            return Kind.DOUBLE, float(payload), False
        except ValueError:
            found, value = classify_payload(payload)
            return found, value, True
    if kind is Kind.STRING:
        try:
            return Kind.STRING, payload.decode("utf-8"), False
        except UnicodeDecodeError:
            return Kind.BINARY, payload, True
    return Kind.BINARY, payload, False


def encode_value(value: float | str | bytes) -> tuple[Kind, bytes]:
    """Return the kind and payload bytes of a value."""
    if type(value) is float:  # the common case first: one check instead of four
        if value != value:
            return Kind.DOUBLE, _nan_text(value)
        return Kind.DOUBLE, repr(value).encode("ascii")
    if isinstance(value, bytes | bytearray | memoryview):
        return Kind.BINARY, bytes(value)
    if isinstance(value, str):
        # surrogateescape: a value read from an alog with non-UTF-8 bytes goes out as those
        # bytes (what the MOOS process published), not as an exception.
        return Kind.STRING, value.encode("utf-8", "surrogateescape")
    if isinstance(value, bool):
        msg = "a MOOS value is a float, a str or bytes, not a bool"
        raise TypeError(msg)
    number = float(value)
    return Kind.DOUBLE, _nan_text(number) if number != number else repr(number).encode("ascii")


def _nan_text(value: float) -> bytes:
    # repr() drops a NaN's sign; C++ (and so pLogger) prints "-nan", and float() reads it.
    return b"-nan" if math.copysign(1.0, value) < 0 else b"nan"


@dataclass(frozen=True, slots=True)
class Meta:
    """The MOOS metadata an attachment carries."""

    time: float
    source: str
    aux: str
    community: str
    original_time: float | None = None


def _leb128(n: int) -> bytes:
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _put_str(out: bytearray, text: str) -> None:
    # The attachment's strings must be UTF-8 for every reader: a byte that is not (a source
    # read from a Latin-1 alog, carried as a surrogate escape) is sent as "?".
    raw = text.encode("utf-8", "replace")
    out += _leb128(len(raw))
    out += raw


_encoded_tails: dict[tuple[str, str, str], bytes] = {}
#: packs an attachment's time fields: ``encode_attachment(t, s, a, c, o)`` is
#: ``TIME_FIELD.pack(t) + attachment_tail(s, a, c) + TIME_FIELD.pack(o)``
TIME_FIELD = _F64


def attachment_tail(source: str, aux: str = "", community: str = "") -> bytes:
    """Return the attachment's bytes between its time and its original time (the strings).

    A publisher whose origin never changes builds them once (:data:`TIME_FIELD`).
    """
    return _encoded_tail(source, aux, community)


def _encoded_tail(source: str, aux: str, community: str) -> bytes:
    ident = (source, aux, community)
    tail = _encoded_tails.get(ident)
    if tail is None:
        out = bytearray()
        _put_str(out, source)
        _put_str(out, aux)
        _put_str(out, community)
        tail = bytes(out)
        if len(_encoded_tails) > 4096:
            _encoded_tails.clear()
        _encoded_tails[ident] = tail
    return tail


def encode_attachment(
    time: float,
    source: str = "",
    aux: str = "",
    community: str = "",
    original_time: float | None = None,
) -> bytes:
    """Serialize MOOS metadata as zenoh-ext serializes ``(f64, str, str, str[, f64])``."""
    # Publishers repeat the same (source, aux, community): their bytes are built once.
    tail = _encoded_tail(source, aux, community)
    if original_time is None:
        return _F64.pack(time) + tail
    return _F64.pack(time) + tail + _F64.pack(original_time)


def _get_str(data: bytes, pos: int) -> tuple[str, int]:
    length = 0
    shift = 0
    while True:
        if pos >= len(data) or shift > 35:
            msg = "attachment ends inside a string length"
            raise FormatError(msg)
        byte = data[pos]
        pos += 1
        length |= (byte & 0x7F) << shift
        if not byte & 0x80:
            break
        shift += 7
    end = pos + length
    if end > len(data):
        msg = "attachment ends inside a string"
        raise FormatError(msg)
    try:
        return data[pos:end].decode("utf-8"), end
    except UnicodeDecodeError:
        msg = "attachment string is not UTF-8"
        raise FormatError(msg) from None


_tail_cache: dict[bytes, tuple[str, str, str]] = {}
_unpack_f64 = _F64.unpack_from


def attachment_fields(data: bytes) -> tuple[float, str, str, str, float | None]:
    """Decode an attachment into ``(time, source, aux, community, original_time)``.

    What :func:`decode_attachment` returns, as a plain tuple: the recorder's hot path
    decodes one per sample and skips building a :class:`Meta`.

    Raises:
        FormatError: the bytes are not such an attachment.
    """
    if len(data) < 11:
        msg = f"attachment of {len(data)} bytes is too short for (time, source, aux, community)"
        raise FormatError(msg)
    tail = data[8:]
    cached = _tail_cache.get(tail)
    if cached is not None:
        source, aux, community = cached
        return _unpack_f64(data, 0)[0], source, aux, community, None
    (time,) = _unpack_f64(data, 0)
    source, pos = _get_str(data, 8)
    aux, pos = _get_str(data, pos)
    community, pos = _get_str(data, pos)
    original: float | None = None
    if len(data) >= pos + 8:
        (original,) = _unpack_f64(data, pos)
    elif pos == len(data):
        # The common case (no replay time): the tail repeats per publisher, cache its parse.
        if len(_tail_cache) > 4096:
            _tail_cache.clear()
        _tail_cache[tail] = (source, aux, community)
    return time, source, aux, community, original


def decode_attachment(data: bytes) -> Meta:
    """Decode an attachment made by :func:`encode_attachment` (or zenoh-ext's serializer).

    Trailing fields this version does not know are ignored, so the tuple can grow.

    Raises:
        FormatError: the bytes are not such an attachment.
    """
    return Meta(*attachment_fields(data))


@dataclass(frozen=True, slots=True)
class MoosMessage:
    """A MOOS message as fleetlog moves it: what a publisher sends and the recorder logs.

    Attributes:
        name: the MOOS variable name.
        value: float (double), str (string) or bytes (binary).
        time: the message time, seconds since the epoch (MOOS's ``m_dfTime``).
        source: the publishing process (``m_sSrc``).
        aux: the aux source (``m_sSrcAux``), for example a helm behaviour.
        community: the originating community (vehicle) of the message.
        original_time: for replayed samples, the recorded absolute time.
    """

    name: str
    value: float | str | bytes
    time: float
    source: str = ""
    aux: str = ""
    community: str = ""
    original_time: float | None = None

    @property
    def kind(self) -> Kind:
        """The value's MOOS type."""
        if isinstance(self.value, bytes):
            return Kind.BINARY
        if isinstance(self.value, str):
            return Kind.STRING
        return Kind.DOUBLE


_MESSAGE_FIELDS = ("name", "value", "time", "source", "aux", "community", "original_time")
_message_setters = tuple(MoosMessage.__dict__[f].__set__ for f in _MESSAGE_FIELDS)


def new_message(
    name: str,
    value: float | str | bytes,
    time: float,
    source: str,
    aux: str,
    community: str,
    original_time: float | None,
) -> MoosMessage:
    """Build ``MoosMessage(name, value, time, source, aux, community, original_time)``.

    The same frozen object, built in about half the time: a frozen dataclass's ``__init__``
    goes through ``object.__setattr__`` for each of the seven fields, which the recorder pays
    on every sample; this sets the slots directly.
    """
    msg = object.__new__(MoosMessage)
    s_name, s_value, s_time, s_source, s_aux, s_community, s_original = _message_setters
    s_name(msg, name)
    s_value(msg, value)
    s_time(msg, time)
    s_source(msg, source)
    s_aux(msg, aux)
    s_community(msg, community)
    s_original(msg, original_time)
    return msg
