"""The MOOS protocol codec against real traffic (tests/data/reference/moos-wire)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest
from helpers import REFERENCE

from fleetlog.errors import FormatError
from fleetlog.moos.protocol import (
    MESSAGE_OVERHEAD,
    PACKET_HEADER,
    DataType,
    Message,
    MsgType,
    PacketReader,
    decode_message,
    decode_packet,
    decode_stream,
    encode_message,
    encode_packet,
)
from fleetlog.moos.requests import (
    HANDSHAKE,
    handshake_message,
    notify,
    parse_welcome,
    register,
    timing_message,
    wildcard_register,
)

WIRE = REFERENCE / "moos-wire"
FILES = sorted(WIRE.glob("*.bin"))


def _body(path: Path) -> bytes:
    data = path.read_bytes()
    if "client-to-db" in path.name:
        assert data[:32] == HANDSHAKE
        return data[32:]
    return data


def _packets(path: Path) -> list[bytes]:
    """The file cut into packets by their length fields alone (no decoding)."""
    data = _body(path)
    out = []
    pos = 0
    while pos < len(data):
        (size,) = struct.unpack_from("<i", data, pos)
        out.append(data[pos : pos + size])
        pos += size
    assert pos == len(data)
    return out


ALL_PACKETS = [(f.name, i, p) for f in FILES for i, p in enumerate(_packets(f))]


def test_the_reference_traffic_is_there() -> None:
    assert len(FILES) == 4
    assert len(ALL_PACKETS) == 62


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_every_packet_decodes_and_reencodes_to_the_same_bytes(path: Path) -> None:
    body = _body(path)
    packets = decode_stream(body)
    assert b"".join(encode_packet(m) for m in packets) == body
    for messages in packets:
        for message in messages:
            assert encode_message(message) == encode_message(
                decode_message(encode_message(message))
            )
            assert message.size() == len(encode_message(message))


def test_what_pub1_sent_is_what_sub1_received() -> None:
    sent = [
        m
        for pkt in decode_stream(_body(WIRE / "conn2.client-to-db.bin"))
        for m in pkt
        if m.msg_type == MsgType.NOTIFY and m.key in ("BAR_X", "BAR_B")
    ]
    received = [
        m
        for pkt in decode_stream(_body(WIRE / "conn1.db-to-client.bin"))
        for m in pkt
        if m.msg_type == MsgType.NOTIFY and m.key in ("BAR_X", "BAR_B")
    ]
    assert [m.double for m in sent if m.key == "BAR_X"] == [float(i) for i in range(25)]
    binary = [m for m in sent if m.key == "BAR_B"]
    assert binary
    assert all(m.data_type == DataType.BINARY and len(m.string) == 16 for m in binary)
    # The DB delivers each message unchanged, in order, but for the community it fills in
    # (umm stamps several posts with one time: only the order tells them apart).
    assert len(received) >= 20
    first = received[0]
    offset = next(
        i
        for i, m in enumerate(sent)
        if (m.key, m.time, m.double, m.string)
        == (first.key, first.time, first.double, first.string)
    )
    for got, original in zip(received, sent[offset:], strict=False):
        assert got._replace(community="", id=original.id) == original
        assert got.community == "#1"
        assert got.source == "pub1"


def test_the_handshake_as_the_reference_client_sent_it() -> None:
    first = decode_stream(_body(WIRE / "conn1.client-to-db.bin"))[0]
    assert first == [handshake_message("sub1", first[0].time)]
    assert encode_packet(first) == _packets(WIRE / "conn1.client-to-db.bin")[0]


def test_the_welcome() -> None:
    welcome = parse_welcome(decode_stream(_body(WIRE / "conn1.db-to-client.bin"))[0])
    assert welcome.community == "#1"
    assert welcome.host == "vm"
    assert welcome.asynchronous
    assert 0.05 < welcome.skew < 0.2  # the DB's 100 ms pause, not a clock offset


def test_a_poison_message_is_a_refusal() -> None:
    poison = Message(
        MsgType.POISON, DataType.STRING, "", 0.0, string=b'A client of this name ("x") already'
    )
    with pytest.raises(FormatError, match=r"refused the connection: A client of this name"):
        parse_welcome([poison])
    with pytest.raises(FormatError, match="empty packet"):
        parse_welcome([])
    with pytest.raises(FormatError, match="'N' message"):
        parse_welcome([notify("X", 1.0, 0.0, "a")])


def test_the_documented_example_packet() -> None:
    # MOOS_WIRE.md §2: NAV_X=1.5 from "app" at 1700000000.25, id 7, is 71 bytes.
    message = notify("NAV_X", 1.5, 1700000000.25, "app")._replace(id=7)
    packet = encode_packet([message])
    assert len(packet) == 71
    assert packet[:9] == bytes.fromhex("470000000100000000")
    assert packet[9:13] == bytes.fromhex("3e000000")
    assert decode_packet(packet) == [message]


@pytest.mark.parametrize(("name", "index", "packet"), ALL_PACKETS, ids=lambda x: str(x)[:20])
def test_every_prefix_of_every_packet_is_refused(name: str, index: int, packet: bytes) -> None:
    for cut in range(len(packet)):
        with pytest.raises(FormatError):
            decode_packet(packet[:cut])


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_the_reader_reassembles_byte_by_byte(path: Path) -> None:
    body = _body(path)
    reader = PacketReader()
    got = []
    for i in range(len(body)):
        got.extend(reader.feed(body[i : i + 1]))
        # a packet is returned the moment its last byte arrives, not before
    assert got == decode_stream(body)
    assert reader.pending == 0


def test_a_stream_cut_inside_a_packet_is_an_error() -> None:
    body = _body(WIRE / "conn2.client-to-db.bin")
    with pytest.raises(FormatError, match="stream ends inside a packet"):
        decode_stream(body[:-1])


def test_a_packet_over_the_limit_is_skipped_and_the_stream_stays_in_step() -> None:
    big = encode_packet([notify("IMG", b"\x01" * 5000, 1.0, "cam")])
    small = encode_packet([notify("NAV_X", 2.0, 2.0, "gps")])
    reader = PacketReader(max_size=1000)
    got = []
    data = small + big + small + big[:100]
    for i in range(0, len(data), 7):
        got.extend(reader.feed(data[i : i + 7]))
    got.extend(reader.feed(big[100:] + small))
    assert [m[0].key for m in got] == ["NAV_X", "NAV_X", "NAV_X"]
    assert reader.oversized == 2
    assert reader.oversized_messages == 2
    assert reader.pending == 0
    with pytest.raises(FormatError, match="larger than the limit of 1000"):
        decode_packet(big, max_size=1000)


def test_a_huge_announced_length_is_not_allocated() -> None:
    reader = PacketReader(max_size=1 << 20)
    header = struct.pack("<iiB", 0x7FFF0000, 1, 0)
    assert reader.feed(header + b"x" * 100) == []
    assert reader.oversized == 1
    assert reader.pending == 0  # nothing held: the rest is skipped as it comes


@pytest.mark.parametrize(
    ("packet", "reason"),
    [
        (struct.pack("<iiB", 8, 0, 0), "shorter than its header"),
        (struct.pack("<iiB", 9, -1, 0), "cannot hold -1 messages"),
        (struct.pack("<iiB", 9, 1, 0), "cannot hold 1 messages"),
        (struct.pack("<iiB", 9, 0, 0) + b"x", "packet length says 9 bytes, got 10"),
        (struct.pack("<iiB", 9 + 54, 1, 0) + struct.pack("<i", 10) + bytes(50), "length 10"),
        (struct.pack("<iiB", 69, 1, 0) + struct.pack("<i", 54) + bytes(56), "6 bytes after"),
    ],
)
def test_malformed_packets_name_what_is_wrong(packet: bytes, reason: str) -> None:
    with pytest.raises(FormatError, match=reason):
        decode_packet(packet)


def test_negative_string_lengths_are_refused() -> None:
    good = encode_message(notify("K", "v", 1.0, "s"))
    for offset in (10, 14 + 1, 14 + 5, 14 + 9):  # the four text lengths
        (n,) = struct.unpack_from("<i", good, offset) if offset != 10 else (0,)
        bad = bytearray(good)
        if offset == 10:
            bad[10:14] = struct.pack("<i", -5)
        else:
            bad[offset : offset + 4] = struct.pack("<i", -1 - n)
        with pytest.raises(FormatError):
            decode_message(bytes(bad))


def test_values_of_every_type_survive_exactly() -> None:
    weird = "Ünïcode \x00 and a lone \udcff byte"
    messages = [
        notify("D", -0.0, 1.5, "a"),
        notify("N", float("-nan"), 2.5, "a"),
        notify("I", math.inf, 3.5, "a"),
        notify("S", weird, 4.5, "src\udc80", "aux", "#1"),
        notify("B", bytes(range(256)), 5.5, "cam"),
        notify("E", "", 6.5, ""),
    ]
    decoded = decode_packet(encode_packet(messages))
    assert [m.key for m in decoded] == ["D", "N", "I", "S", "B", "E"]
    assert math.copysign(1, decoded[0].double) == -1
    assert math.isnan(decoded[1].double)
    assert math.copysign(1, decoded[1].double) == -1
    assert decoded[3].value == weird
    assert decoded[3].source == "src\udc80"
    assert decoded[4].value == bytes(range(256))
    assert decoded[5].value == ""
    assert [encode_message(m) for m in decoded] == [encode_message(m) for m in messages]


def test_control_messages() -> None:
    t = timing_message(12.0)
    assert (t.msg_type, t.key, t.double) == ("T", "_async_timing", 0.0)
    r = register("me", "NAV_X", 0.5, 1.0)
    assert (r.msg_type, r.source, r.double) == ("R", "me", 0.5)
    w = wildcard_register("me", "NAV_*", "*", 0.0, 1.0)
    assert w.msg_type == "*"
    assert w.key == "me"
    assert w.string == b"AppPattern=*,VarPattern=NAV_*,Interval=0.000000"
    with pytest.raises(ValueError, match="cannot hold"):
        wildcard_register("me", "A,B", "*", 0.0, 1.0)
    with pytest.raises(ValueError, match="one character"):
        encode_message(t._replace(msg_type="TT"))


def test_sizes() -> None:
    assert len(encode_message(Message("N", "D", "", 0.0))) == MESSAGE_OVERHEAD
    assert len(encode_packet([])) == PACKET_HEADER
