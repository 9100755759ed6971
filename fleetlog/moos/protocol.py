"""The MOOS V10 wire protocol: messages, packets and framing (MOOS_WIRE.md §2-3).

Pure code: bytes in, messages out, and back. The socket I/O lives in
:mod:`fleetlog.transport.moos_client`.

* A **message** (``CMOOSMsg``) is: int32 total length (these 4 bytes included), int32 id,
  one byte message type, one byte data type, four strings (source, aux source, originating
  community, key), three float64 (time, double value, second double) and a last string (the
  string or binary value). A string is an int32 byte count and the raw bytes: no terminator,
  no encoding. Everything is little-endian.
* A **packet** (``CMOOSCommPkt``) is: int32 total length (its 9-byte header included), int32
  message count, one "compressed" byte (always written 0, ignored on read), then the
  messages back to back.
* The **handshake** and the messages a client sends are in :mod:`fleetlog.moos.requests`.

Text fields (source, aux, community, key) are decoded as UTF-8 with ``surrogateescape``, so
any bytes survive a decode and re-encode unchanged; the value string stays ``bytes``. The
decoder is strict: a length that does not add up, a negative count, a packet larger than the
reader's limit or bytes left over raise :class:`~fleetlog.errors.FormatError` with the reason.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import NamedTuple

from fleetlog.errors import FormatError

__all__ = [
    "DEFAULT_MAX_PACKET",
    "MESSAGE_OVERHEAD",
    "PACKET_HEADER",
    "DataType",
    "Message",
    "MsgType",
    "PacketReader",
    "decode_message",
    "decode_packet",
    "decode_stream",
    "encode_message",
    "encode_packet",
]

#: Bytes of a message with empty strings: 2 int32, 2 chars, 5 string lengths, 3 float64.
MESSAGE_OVERHEAD = 54
#: Bytes of a packet header: int32 length, int32 count, one flag byte.
PACKET_HEADER = 9
#: Default largest packet a reader accepts (MOOS itself has no limit; a camera image is a few
#: MiB, and a corrupt or hostile length must not make the reader allocate gigabytes).
DEFAULT_MAX_PACKET = 64 * 1024 * 1024


class MsgType:
    """Message types (``m_cMsgType``, ``MOOSMsg.h``)."""

    NOTIFY = "N"
    REGISTER = "R"
    UNREGISTER = "U"
    WILDCARD_REGISTER = "*"
    WILDCARD_UNREGISTER = "/"
    NOT_SET = "~"
    COMMAND = "C"
    ANONYMOUS = "A"
    NULL = "."
    DATA = "i"
    POISON = "K"
    WELCOME = "W"
    SERVER_REQUEST = "Q"
    TIMING = "T"
    TERMINATE = "^"


class DataType:
    """Data types (``m_cDataType``)."""

    DOUBLE = "D"
    STRING = "S"
    BINARY = "B"


class Message(NamedTuple):
    """One ``CMOOSMsg``, every field as it travels.

    Attributes:
        msg_type: one character, see :class:`MsgType`.
        data_type: one character, see :class:`DataType`.
        key: the variable name (or, for control messages, what they are about).
        time: ``m_dfTime``, seconds since the epoch.
        double: ``m_dfVal`` (-1 when unused).
        string: ``m_sVal`` as raw bytes: the string or binary value.
        source: ``m_sSrc``, the publishing process.
        aux: ``m_sSrcAux``, the auxiliary source.
        community: ``m_sOriginatingCommunity``.
        double2: ``m_dfVal2`` (-1 when unused; the DB's pacing period in timing replies).
        id: ``m_nID``.
    """

    msg_type: str
    data_type: str
    key: str
    time: float
    double: float = -1.0
    string: bytes = b""
    source: str = ""
    aux: str = ""
    community: str = ""
    double2: float = -1.0
    id: int = -1

    @property
    def value(self) -> float | str | bytes:
        """The value as fleetlog carries it: float, str (surrogate-escaped) or bytes."""
        if self.data_type == DataType.DOUBLE:
            return self.double
        if self.data_type == DataType.BINARY:
            return self.string
        return self.string.decode("utf-8", "surrogateescape")

    def size(self) -> int:
        """Return the message's length on the wire."""
        return (
            MESSAGE_OVERHEAD
            + len(_text(self.source))
            + len(_text(self.aux))
            + len(_text(self.community))
            + len(_text(self.key))
            + len(self.string)
        )


_new_message = Message.__new__
_I32 = struct.Struct("<i")
_HEAD = struct.Struct("<iiBBi")  # length, id, type, data type, source length
_TAIL = struct.Struct("<dddi")  # time, double, double2, string length
_PACKET = struct.Struct("<iiB")
_CHR = [chr(i) for i in range(256)]
_unpack_i32 = _I32.unpack_from
_unpack_head = _HEAD.unpack_from
_unpack_tail = _TAIL.unpack_from


def _text(text: str) -> bytes:
    return text.encode("utf-8", "surrogateescape")


def _type_byte(char: str, what: str) -> int:
    raw = char.encode("latin-1", "replace") if char else b""
    if len(raw) != 1:
        msg = f"a message's {what} must be one character, not {char!r}"
        raise ValueError(msg)
    return raw[0]


def encode_message(message: Message) -> bytes:
    """Serialize one message as ``CMOOSMsg::Serialize`` does.

    Raises:
        ValueError: the message or data type is not one character.
    """
    source = _text(message.source)
    aux = _text(message.aux)
    community = _text(message.community)
    key = _text(message.key)
    value = message.string
    length = MESSAGE_OVERHEAD + len(source) + len(aux) + len(community) + len(key) + len(value)
    return b"".join(
        (
            _HEAD.pack(
                length,
                message.id,
                _type_byte(message.msg_type, "type"),
                _type_byte(message.data_type, "data type"),
                len(source),
            ),
            source,
            _I32.pack(len(aux)),
            aux,
            _I32.pack(len(community)),
            community,
            _I32.pack(len(key)),
            key,
            _TAIL.pack(message.time, message.double, message.double2, len(value)),
            value,
        )
    )


def encode_packet(messages: Iterable[Message]) -> bytes:
    """Serialize messages into one packet (``CMOOSCommPkt``).

    Raises:
        ValueError: a message's type or data type is not one character.
    """
    body = [encode_message(m) for m in messages]
    size = PACKET_HEADER + sum(len(b) for b in body)
    return _PACKET.pack(size, len(body), 0) + b"".join(body)


def _length(data: bytes | memoryview, pos: int, stop: int, what: str) -> int:
    if pos + 4 > stop:
        msg = f"message ends inside the length of its {what}"
        raise FormatError(msg)
    n: int = _unpack_i32(data, pos)[0]
    if n < 0 or pos + 4 + n > stop:
        msg = f"message's {what} claims {n} bytes, {stop - pos - 4} are left"
        raise FormatError(msg)
    return n


#: the text fields of recent messages: their bytes → (source, aux, community, key). A sender
#: repeats the same few, and one lookup replaces four slices and four decodes.
_texts: dict[bytes, tuple[str, str, str, str]] = {}


def _decode_texts(region: bytes, nsrc: int, naux: int, ncom: int) -> tuple[str, str, str, str]:
    a = nsrc + 4
    c = a + naux + 4
    k = c + ncom + 4
    texts = (
        region[:nsrc].decode("utf-8", "surrogateescape"),
        region[a : a + naux].decode("utf-8", "surrogateescape"),
        region[c : c + ncom].decode("utf-8", "surrogateescape"),
        region[k:].decode("utf-8", "surrogateescape"),
    )
    if len(_texts) >= 4096:
        _texts.clear()
    _texts[region] = texts
    return texts


def decode_message(data: bytes | memoryview, pos: int = 0, end: int | None = None) -> Message:
    """Decode the message at ``pos``; it must end exactly where its length says.

    Args:
        data: the bytes holding it.
        pos: where it starts.
        end: where the enclosing packet ends (the end of ``data`` by default).

    Raises:
        FormatError: the bytes are not one whole message.
    """
    limit = len(data) if end is None else end
    if pos + 14 > limit:
        msg = f"message header needs 14 bytes, {limit - pos} are left"
        raise FormatError(msg)
    length, ident, mtype, dtype, nsrc = _unpack_head(data, pos)
    if length < MESSAGE_OVERHEAD or pos + length > limit:
        msg = f"message length {length} does not fit: {limit - pos} bytes are left"
        raise FormatError(msg)
    stop = pos + length
    p = pos + 14
    if nsrc < 0 or p + nsrc > stop:
        msg = f"message's source claims {nsrc} bytes, {stop - p} are left"
        raise FormatError(msg)
    q = p + nsrc
    naux = _length(data, q, stop, "aux source")
    q += 4 + naux
    ncom = _length(data, q, stop, "community")
    q += 4 + ncom
    nkey = _length(data, q, stop, "key")
    q += 4 + nkey
    if q + 28 > stop:
        msg = "message ends inside its time and values"
        raise FormatError(msg)
    when, double, double2, nval = _unpack_tail(data, q)
    if nval < 0 or q + 28 + nval != stop:
        msg = f"message's value claims {nval} bytes, {stop - q - 28} are left"
        raise FormatError(msg)
    region = bytes(data[p:q])
    texts = _texts.get(region)
    if texts is None:
        texts = _decode_texts(region, nsrc, naux, ncom)
    source, aux, community, key = texts
    return _new_message(
        Message,
        _CHR[mtype],
        _CHR[dtype],
        key,
        when,
        double,
        bytes(data[q + 28 : stop]),
        source,
        aux,
        community,
        double2,
        ident,
    )


def _decode_body(data: bytes | memoryview, start: int, end: int, count: int) -> list[Message]:
    messages: list[Message] = []
    pos = start
    for index in range(count):
        if pos + 4 > end:
            msg = f"packet announces {count} messages but ends after {index}"
            raise FormatError(msg)
        message = decode_message(data, pos, end)
        pos += _unpack_i32(data, pos)[0]
        messages.append(message)
    if pos != end:
        msg = f"packet has {end - pos} bytes after its {count} messages"
        raise FormatError(msg)
    return messages


def decode_packet(data: bytes | memoryview, max_size: int = DEFAULT_MAX_PACKET) -> list[Message]:
    """Decode exactly one packet.

    Raises:
        FormatError: ``data`` is not exactly one well-formed packet, or it is larger than
            ``max_size``.
    """
    if len(data) < PACKET_HEADER:
        msg = f"packet header needs {PACKET_HEADER} bytes, got {len(data)}"
        raise FormatError(msg)
    size, count, _flag = _PACKET.unpack_from(data, 0)
    _check_header(size, count, max_size)
    if size != len(data):
        msg = f"packet length says {size} bytes, got {len(data)}"
        raise FormatError(msg)
    return _decode_body(data, PACKET_HEADER, size, count)


def _check_header(size: int, count: int, max_size: int) -> None:
    if size < PACKET_HEADER:
        msg = f"packet length {size} is shorter than its header"
        raise FormatError(msg)
    if size > max_size:
        msg = f"packet of {size} bytes is larger than the limit of {max_size}"
        raise FormatError(msg)
    if count < 0 or count * MESSAGE_OVERHEAD > size - PACKET_HEADER:
        msg = f"packet of {size} bytes cannot hold {count} messages"
        raise FormatError(msg)


class PacketReader:
    """Cuts a byte stream into packets and decodes them (the receive side's framing).

    Feed it whatever the socket delivers; it returns the messages of every packet completed.
    A packet larger than ``max_size`` is not buffered: its bytes are skipped as they arrive
    (the stream stays in step) and counted in :attr:`oversized`. Any other malformed packet
    raises :class:`FormatError`, after which the stream cannot be trusted.

    Args:
        max_size: the largest packet accepted, in bytes.
    """

    __slots__ = ("_buffer", "_skip", "max_size", "oversized", "oversized_messages")

    def __init__(self, max_size: int = DEFAULT_MAX_PACKET) -> None:
        self.max_size = max_size
        self._buffer = bytearray()
        self._skip = 0
        #: packets skipped because they were larger than ``max_size``
        self.oversized = 0
        #: messages those packets announced
        self.oversized_messages = 0

    @property
    def pending(self) -> int:
        """Bytes held of a packet not yet complete."""
        return len(self._buffer)

    def feed(self, data: bytes | bytearray | memoryview) -> list[list[Message]]:
        """Take received bytes; return the messages of each packet they completed, in order.

        Raises:
            FormatError: a packet is malformed (other than too large).
        """
        if self._skip:
            take = min(self._skip, len(data))
            self._skip -= take
            data = data[take:]
        buffer = self._buffer
        buffer += data
        packets: list[list[Message]] = []
        pos = 0
        end = len(buffer)
        view = memoryview(buffer)
        try:
            while end - pos >= PACKET_HEADER:
                size, count, _flag = _PACKET.unpack_from(buffer, pos)
                if size > self.max_size and size >= PACKET_HEADER:
                    self.oversized += 1
                    self.oversized_messages += max(count, 0)
                    have = end - pos
                    if have >= size:
                        pos += size
                        continue
                    self._skip = size - have
                    pos = end
                    break
                _check_header(size, count, self.max_size)
                if end - pos < size:
                    break
                packets.append(_decode_body(view, pos + PACKET_HEADER, pos + size, count))
                pos += size
        finally:
            view.release()
        if pos:
            del buffer[:pos]
        return packets


def decode_stream(data: bytes, max_size: int = DEFAULT_MAX_PACKET) -> list[list[Message]]:
    """Decode back-to-back whole packets (a recorded direction of a connection).

    Raises:
        FormatError: a packet is malformed, or the bytes end inside one.
    """
    reader = PacketReader(max_size)
    packets = reader.feed(data)
    if reader.pending or reader.oversized:
        msg = f"stream ends inside a packet ({reader.pending} bytes of it)"
        raise FormatError(msg)
    return packets
