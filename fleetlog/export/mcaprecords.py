"""MCAP records as bytes, written from the MCAP specification (format version 0).

Only the encoding of single records lives here (opcodes, prefixes, strings and maps, the
chunk index and statistics records); how a batch of messages becomes chunks is
:mod:`fleetlog.export.mcapchunks`, and the file's layout :mod:`fleetlog.export.mcapfile`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

__all__ = [
    "MAGIC",
    "MESSAGE_FIXED",
    "OP_CHANNEL",
    "OP_CHUNK",
    "OP_CHUNK_INDEX",
    "OP_DATA_END",
    "OP_FOOTER",
    "OP_HEADER",
    "OP_MESSAGE",
    "OP_MESSAGE_INDEX",
    "OP_SCHEMA",
    "OP_STATISTICS",
    "OP_SUMMARY_OFFSET",
    "PREFIX",
    "ChunkInfo",
    "chunk_index",
    "message_index",
    "record",
    "statistics",
    "string",
    "string_map",
]

MAGIC = b"\x89MCAP0\r\n"

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_STATISTICS = 0x0B
OP_SUMMARY_OFFSET = 0x0E
OP_DATA_END = 0x0F

#: A record's opcode and content length.
PREFIX = struct.Struct("<BQ")
#: The message record's content before its data: channel, sequence, log and publish time.
MESSAGE_FIXED = 22


def string(text: str) -> bytes:
    """A length-prefixed UTF-8 string."""
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def record(opcode: int, content: bytes) -> bytes:
    """A whole record: its prefix, then its content."""
    return PREFIX.pack(opcode, len(content)) + content


def string_map(items: dict[str, str]) -> bytes:
    """A ``map<string, string>``, its keys in order."""
    body = b"".join(string(k) + string(v) for k, v in sorted(items.items()))
    return struct.pack("<I", len(body)) + body


def message_index(channel: int, pairs: bytes) -> bytes:
    """A Message Index record of one channel: ``pairs`` is (log time, offset) as ``<QQ``."""
    return (
        PREFIX.pack(OP_MESSAGE_INDEX, 6 + len(pairs))
        + struct.pack("<HI", channel, len(pairs))
        + pairs
    )


@dataclass
class ChunkInfo:
    """What the summary says of one chunk (its Chunk Index record)."""

    start: int
    end: int
    offset: int = 0
    length: int = 0
    index_offsets: dict[int, int] = field(default_factory=dict)
    index_length: int = 0
    compressed: int = 0
    uncompressed: int = 0


def chunk_index(info: ChunkInfo) -> bytes:
    """The Chunk Index record of a written chunk (zstd)."""
    offsets = b"".join(struct.pack("<HQ", c, o) for c, o in sorted(info.index_offsets.items()))
    content = (
        struct.pack("<QQQQ", info.start, info.end, info.offset, info.length)
        + struct.pack("<I", len(offsets))
        + offsets
        + struct.pack("<Q", info.index_length)
        + string("zstd")
        + struct.pack("<QQ", info.compressed, info.uncompressed)
    )
    return record(OP_CHUNK_INDEX, content)


def statistics(
    counts: dict[int, int], schemas: int, channels: int, chunks: int, start: int, end: int
) -> bytes:
    """The Statistics record: messages per channel, and the file's time span."""
    per_channel = b"".join(struct.pack("<HQ", cid, n) for cid, n in sorted(counts.items()))
    content = (
        struct.pack("<QHIIIIQQ", sum(counts.values()), schemas, channels, 0, 0, chunks, start, end)
        + struct.pack("<I", len(per_channel))
        + per_channel
    )
    return record(OP_STATISTICS, content)
