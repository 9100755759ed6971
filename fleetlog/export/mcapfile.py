"""An MCAP writer that takes messages in batches: indexed, zstd-compressed chunks.

Written from the MCAP specification (format version 0): magic, a Header, then the data
section (Schema and Channel records where first needed, then Chunk records each followed by
its Message Index records), DataEnd, a summary section (Schemas, Channels, Statistics and
Chunk Indexes, each group located by a Summary Offset record), a Footer with the summary's
CRC, and the magic again. Readers (Foxglove, ``mcap`` CLI and libraries) seek with the
summary and the message indexes.

Why not the ``mcap`` package's writer: it builds every record in Python per message; fed
ready-made messages it alone took 2.8 times as long as reading them (docs/bench.md §10), more
than this whole export. Here a batch's messages are sorted by
log time, their headers packed by one precompiled :class:`struct.Struct` mapped over the
batch (a loop in C, not in Python bytecode), cut into chunks
of about :data:`CHUNK_SIZE` uncompressed bytes, and compressed by two worker threads
(``zstandard`` releases the GIL) while the next chunk is packed. Chunks may overlap in
time (several vehicles, late entries); the message indexes let readers merge them.
"""

from __future__ import annotations

import struct
import threading
import zlib
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from itertools import chain, repeat
from typing import TYPE_CHECKING, Any, BinaryIO

from fleetlog.errors import StorageError

if TYPE_CHECKING:
    import polars as pl

__all__ = ["CHUNK_SIZE", "MAGIC", "McapWriter"]

MAGIC = b"\x89MCAP0\r\n"
#: Uncompressed bytes of messages per chunk (what a reader decompresses to reach one).
CHUNK_SIZE = 1 << 20
_IN_FLIGHT = 6
#: zstd workers: compression runs beside the packing (zstandard releases the GIL).
_WORKERS = 2

_OP_HEADER = 0x01
_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07
_OP_CHUNK_INDEX = 0x08
_OP_STATISTICS = 0x0B
_OP_SUMMARY_OFFSET = 0x0E
_OP_DATA_END = 0x0F

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log and publish time
_MESSAGE_FIXED = 22  # the message record's content before its data
_PREFIX = struct.Struct("<BQ")  # a record's opcode and content length
#: The message record's fixed part as a numpy structured type (packed, like _MESSAGE).
_HEADER_FIELDS = [
    ("op", "u1"),
    ("length", "<u8"),
    ("channel", "<u2"),
    ("sequence", "<u4"),
    ("log_time", "<u8"),
    ("publish_time", "<u8"),
]


def _numpy() -> Any:
    """Numpy if it is installed (an optional accelerator), else None."""
    try:
        import numpy
    except ImportError:
        return None
    return numpy


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _record(opcode: int, content: bytes) -> bytes:
    return _PREFIX.pack(opcode, len(content)) + content


def _string_map(items: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in sorted(items.items()))
    return struct.pack("<I", len(body)) + body


@dataclass
class _ChunkInfo:
    start: int
    end: int
    offset: int = 0
    length: int = 0
    index_offsets: dict[int, int] = field(default_factory=dict)
    index_length: int = 0
    compressed: int = 0
    uncompressed: int = 0


@dataclass
class _Pending:
    info: _ChunkInfo
    crc: int
    indexes: dict[int, bytes]
    data: Future[bytes]


class McapWriter:
    """Writes one MCAP file to a binary stream; call :meth:`finish` to complete it.

    Args:
        out: the stream (written sequentially; its position is tracked here).
        library: what wrote the file (the Header's ``library``).
        chunk_size: uncompressed message bytes per chunk.
        level: the zstd level (1: fast and ~5x smaller than JSON text).
        accelerate: assemble records with numpy when it is installed (the same bytes, with
            no Python object per message); False forces the pure-Python path.
    """

    def __init__(
        self,
        out: BinaryIO,
        *,
        library: str = "fleetlog",
        chunk_size: int = CHUNK_SIZE,
        level: int = 1,
        accelerate: bool = True,
    ) -> None:
        import zstandard

        self._numpy: Any = _numpy() if accelerate else None
        self._out = out
        self._pos = 0
        self._chunk_size = max(1024, chunk_size)
        # A compressor is not safe to share between threads: one per worker.
        self._local = threading.local()
        self._level = level
        self._zstandard = zstandard
        self._pool = ThreadPoolExecutor(_WORKERS, thread_name_prefix="fleetlog-mcap")
        self._pending: deque[_Pending] = deque()
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._chunks: list[_ChunkInfo] = []
        self._counts: dict[int, int] = {}
        self._sequence = 0
        self._start: int | None = None
        self._end = 0
        self._finished = False
        self._records: bytes | memoryview = b""
        self._write(MAGIC + _record(_OP_HEADER, _string("") + _string(library)))

    def _write(self, data: bytes) -> None:
        try:
            self._out.write(data)
        except OSError as err:
            msg = f"cannot write the MCAP file: {err.strerror or err}"
            raise StorageError(msg) from None
        self._pos += len(data)

    # -- schemas and channels

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Declare a schema; return its id (from 1)."""
        sid = len(self._schemas) + 1
        content = struct.pack("<H", sid) + _string(name) + _string(encoding)
        record = _record(_OP_SCHEMA, content + struct.pack("<I", len(data)) + data)
        self._schemas.append(record)
        self._write(record)
        return sid

    def add_channel(
        self, topic: str, encoding: str, schema: int, metadata: dict[str, str] | None = None
    ) -> int:
        """Declare a channel; return its id (from 0). At most 65,535 channels.

        Raises:
            StorageError: the file has 65,535 channels already.
        """
        cid = len(self._channels)
        if cid > 0xFFFF:
            msg = f"an MCAP file holds at most 65,535 channels; {topic!r} is one too many"
            raise StorageError(msg)
        content = struct.pack("<HH", cid, schema) + _string(topic) + _string(encoding)
        record = _record(_OP_CHANNEL, content + _string_map(metadata or {}))
        self._channels.append(record)
        self._write(record)
        self._counts[cid] = 0
        return cid

    # -- messages

    def write_batch(self, batch: pl.DataFrame) -> None:
        """Write messages: columns ``channel`` (UInt16), ``log_time`` (UInt64 ns), ``data``.

        ``data`` is Binary (or String, written as UTF-8). Publish time is the log time.
        The batch is sorted by log time (stable) and cut into chunks. All the per-batch
        work (sizes, chunk boundaries, message indexes) is done once by polars; only the
        record headers are packed per message.
        """
        import polars as pl

        if not batch.height:
            return
        frame = (
            batch.select(
                pl.col("channel").cast(pl.UInt16),
                pl.col("log_time").cast(pl.UInt64),
                pl.col("data").cast(pl.Binary),
            )
            .sort("log_time", maintain_order=True)
            .with_columns(size=(pl.col("data").bin.size() + (_MESSAGE_FIXED + 9)).cast(pl.UInt64))
            .with_columns(at=pl.col("size").cum_sum() - pl.col("size"))
            .with_columns(part=(pl.col("at") // self._chunk_size).rle_id())
            .with_columns(offset=pl.col("at") - pl.col("at").min().over("part"))
        )
        # Message indexes: per chunk and channel, (log time, offset) in time order.
        ordered = frame.select("part", "channel", "log_time", "offset").sort(
            "part", "channel", maintain_order=True
        )
        runs = ordered.group_by("part", "channel", maintain_order=True).len().rows()
        sizes = frame.group_by("part", maintain_order=True).agg(
            pl.len(),
            pl.col("log_time").min().alias("start"),
            pl.col("log_time").max(),
            pl.col("at").min().alias("first"),
            pl.col("size").sum().alias("bytes"),
        )
        buffer = self._assemble(frame) if self._numpy is not None else None
        if buffer is not None:
            pairs = self._numpy.empty((ordered.height, 2), dtype="<u8")
            pairs[:, 0] = ordered["log_time"].to_numpy()
            pairs[:, 1] = ordered["offset"].to_numpy()
        else:
            pairs = (
                ordered.select(pl.concat_list("log_time", "offset").explode()).to_series().to_list()
            )
            channels = frame["channel"].to_list()
            times = frame["log_time"].to_list()
            datas = frame["data"].to_list()
            lengths = (frame["size"] - 9).to_list()  # a message record's content length
        row = 0
        pair = 0
        run = 0
        for part, count, start, end, first, size in sizes.rows():
            indexes: dict[int, bytes] = {}
            while run < len(runs) and runs[run][0] == part:
                _, cid, n = runs[run]
                run += 1
                head = _PREFIX.pack(_OP_MESSAGE_INDEX, 6 + 16 * n) + struct.pack("<HI", cid, 16 * n)
                if buffer is not None:
                    indexes[cid] = head + pairs[pair : pair + n].tobytes()
                else:
                    indexes[cid] = head + struct.pack(
                        f"<{2 * n}Q", *pairs[2 * pair : 2 * (pair + n)]
                    )
                pair += n
                self._counts[cid] += n
            if buffer is not None:
                self._records = memoryview(buffer[first : first + size])
                self._sequence += count
            else:
                rows = slice(row, row + count)
                self._chunk(channels[rows], times[rows], datas[rows], lengths[rows])
            self._queue(_ChunkInfo(start, end), indexes)
            row += count

    def _assemble(self, frame: pl.DataFrame) -> Any:
        """The batch's message records in one numpy buffer, or None (data not UTF-8 text).

        Every header is written by one structured-array assignment and scattered into place
        at once, and every message's data copied by one masked assignment: no Python object
        per message. Gives exactly the bytes :meth:`_chunk` gives.
        """
        import polars as pl

        np = self._numpy
        try:
            text = frame["data"].cast(pl.String)
        except pl.exceptions.PolarsError:
            return None  # bytes that are not UTF-8: the pure-Python path copes
        blob = text.str.join("").item().encode()
        n = frame.height
        at = frame["at"].to_numpy().astype("<i8")
        size = frame["size"].to_numpy()
        heads = np.zeros(n, dtype=np.dtype(_HEADER_FIELDS))
        heads["op"] = _OP_MESSAGE
        heads["length"] = size - 9
        heads["channel"] = frame["channel"].to_numpy()
        heads["sequence"] = np.arange(self._sequence, self._sequence + n, dtype="<u8") & 0xFFFFFFFF
        heads["log_time"] = frame["log_time"].to_numpy()
        heads["publish_time"] = heads["log_time"]
        total = int(at[-1] + size[-1])
        out = np.empty(total, dtype=np.uint8)
        where = (at[:, None] + np.arange(_MESSAGE.size)).ravel()
        out[where] = heads.view(np.uint8)
        data = np.ones(total, dtype=bool)
        data[where] = False
        out[data] = np.frombuffer(blob, dtype=np.uint8)
        return out

    def _chunk(
        self, channels: list[int], times: list[int], datas: list[bytes], lengths: list[int]
    ) -> None:
        # map() and join() run the per-message loop in C: no Python bytecode per message.
        first = self._sequence
        self._sequence = first + len(datas)
        sequences = (s & 0xFFFFFFFF for s in range(first, self._sequence))
        heads = map(_MESSAGE.pack, repeat(_OP_MESSAGE), lengths, channels, sequences, times, times)
        self._records = b"".join(chain.from_iterable(zip(heads, datas, strict=True)))

    def _compress(self, records: bytes | memoryview) -> bytes:
        compressor = getattr(self._local, "zstd", None)
        if compressor is None:
            compressor = self._local.zstd = self._zstandard.ZstdCompressor(level=self._level)
        data: bytes = compressor.compress(records)
        return data

    def _queue(self, info: _ChunkInfo, indexes: dict[int, bytes]) -> None:
        records, self._records = self._records, b""
        self._start = info.start if self._start is None else min(self._start, info.start)
        self._end = max(self._end, info.end)
        info.uncompressed = len(records)
        job = self._pool.submit(self._compress, records)
        self._pending.append(_Pending(info, zlib.crc32(records), indexes, job))
        while len(self._pending) > _IN_FLIGHT:
            self._flush_one()

    def _flush_one(self) -> None:
        job = self._pending.popleft()
        data = job.data.result()
        info = job.info
        content = (
            struct.pack("<QQQI", info.start, info.end, info.uncompressed, job.crc)
            + _string("zstd")
            + struct.pack("<Q", len(data))
        )
        info.offset = self._pos
        info.compressed = len(data)
        self._write(_PREFIX.pack(_OP_CHUNK, len(content) + len(data)) + content)
        self._write(data)
        info.length = self._pos - info.offset
        index_start = self._pos
        for cid, record in job.indexes.items():
            info.index_offsets[cid] = self._pos
            self._write(record)
        info.index_length = self._pos - index_start
        self._chunks.append(info)

    # -- the end

    def finish(self) -> None:
        """Write the remaining chunks, the summary and the footer."""
        if self._finished:
            return
        try:
            while self._pending:
                self._flush_one()
        finally:
            self._pool.shutdown(wait=True)
        self._finished = True
        self._write(_record(_OP_DATA_END, struct.pack("<I", 0)))
        summary_start = self._pos
        groups: list[tuple[int, bytes]] = [
            (_OP_SCHEMA, b"".join(self._schemas)),
            (_OP_CHANNEL, b"".join(self._channels)),
            (_OP_STATISTICS, self._statistics()),
            (_OP_CHUNK_INDEX, b"".join(map(_chunk_index, self._chunks))),
        ]
        summary = bytearray()
        offsets = bytearray()
        for opcode, data in groups:
            if data:
                offsets += _record(
                    _OP_SUMMARY_OFFSET,
                    struct.pack("<BQQ", opcode, summary_start + len(summary), len(data)),
                )
                summary += data
        offsets_start = summary_start + len(summary)
        footer_head = _PREFIX.pack(_OP_FOOTER, 20) + struct.pack(
            "<QQ", summary_start, offsets_start
        )
        crc = zlib.crc32(bytes(summary) + bytes(offsets) + footer_head)
        self._write(bytes(summary) + bytes(offsets) + footer_head + struct.pack("<I", crc) + MAGIC)

    def abort(self) -> None:
        """Stop the compression thread without completing the file (an error upstream)."""
        self._finished = True
        self._pool.shutdown(wait=True, cancel_futures=True)

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in sorted(self._counts.items()))
        content = (
            struct.pack(
                "<QHIIIIQQ",
                sum(self._counts.values()),
                len(self._schemas),
                len(self._channels),
                0,
                0,
                len(self._chunks),
                self._start or 0,
                self._end,
            )
            + struct.pack("<I", len(counts))
            + counts
        )
        return _record(_OP_STATISTICS, content)

    @property
    def messages(self) -> int:
        """Messages written so far."""
        return self._sequence


def _chunk_index(info: _ChunkInfo) -> bytes:
    offsets = b"".join(struct.pack("<HQ", c, o) for c, o in sorted(info.index_offsets.items()))
    content = (
        struct.pack("<QQQQ", info.start, info.end, info.offset, info.length)
        + struct.pack("<I", len(offsets))
        + offsets
        + struct.pack("<Q", info.index_length)
        + _string("zstd")
        + struct.pack("<QQ", info.compressed, info.uncompressed)
    )
    return _record(_OP_CHUNK_INDEX, content)
