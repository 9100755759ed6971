"""An MCAP writer that takes messages in batches: indexed, zstd-compressed chunks.

Written from the MCAP specification (format version 0): magic, a Header, then the data
section (Schema and Channel records where first needed, then Chunk records each followed by
its Message Index records), DataEnd, a summary section (Schemas, Channels, Statistics and
Chunk Indexes, each group located by a Summary Offset record), a Footer with the summary's
CRC, and the magic again. Readers (Foxglove, ``mcap`` CLI and libraries) seek with the
summary and the message indexes.

Why not the ``mcap`` package's writer: it builds every record in Python per message; fed
ready-made messages it alone took 2.8 times as long as reading them (docs/bench.md §10), more
than this whole export. Here each batch is turned into chunks
(:func:`~fleetlog.export.mcapchunks.build_chunks`: sorted, cut, indexed, assembled without a
Python object per message where numpy is installed), checksummed and compressed by one of
two worker threads (polars, numpy, zlib and zstandard release the GIL), while the caller
reads and encodes the next batch. Chunks are placed in the file in the order the batches
came, so the file is the same whatever the threads' timing. Chunks may overlap in time
(several vehicles, late entries); the message indexes let readers merge them.
"""

from __future__ import annotations

import struct
import threading
import zlib
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, BinaryIO

from fleetlog.errors import StorageError
from fleetlog.export.mcapchunks import build_chunks
from fleetlog.export.mcaprecords import (
    MAGIC,
    OP_CHANNEL,
    OP_CHUNK,
    OP_CHUNK_INDEX,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_SCHEMA,
    OP_STATISTICS,
    OP_SUMMARY_OFFSET,
    PREFIX,
    ChunkInfo,
    chunk_index,
    record,
    statistics,
    string,
    string_map,
)

if TYPE_CHECKING:
    import polars as pl

    #: A batch of messages, or what computes it.
    _Batch = pl.DataFrame | pl.LazyFrame | Callable[[], pl.DataFrame]

__all__ = ["CHUNK_SIZE", "MAGIC", "McapWriter"]

#: Uncompressed bytes of messages per chunk (what a reader decompresses to reach one).
CHUNK_SIZE = 1 << 20
#: Batches being built at once: the workers' and one waiting (bounds memory).
_IN_FLIGHT = 3
#: Workers: each builds, checksums and compresses a whole batch's chunks.
_WORKERS = 2


def _numpy() -> Any:
    """Numpy if it is installed (an optional accelerator), else None."""
    try:
        import numpy
    except ImportError:
        return None
    return numpy


@dataclass
class _Packed:
    """A chunk ready for the file."""

    info: ChunkInfo
    crc: int
    indexes: dict[int, bytes]
    counts: dict[int, int]
    data: bytes


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
        self._pending: deque[Future[list[_Packed]]] = deque()
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._chunks: list[ChunkInfo] = []
        self._counts: dict[int, int] = {}
        self._sequence = 0
        self._start: int | None = None
        self._end = 0
        self._finished = False
        self._write(MAGIC + record(OP_HEADER, string("") + string(library)))

    def _write(self, data: bytes | memoryview) -> None:
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
        content = struct.pack("<H", sid) + string(name) + string(encoding)
        schema = record(OP_SCHEMA, content + struct.pack("<I", len(data)) + data)
        self._schemas.append(schema)
        self._write(schema)
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
        content = struct.pack("<HH", cid, schema) + string(topic) + string(encoding)
        channel = record(OP_CHANNEL, content + string_map(metadata or {}))
        self._channels.append(channel)
        self._write(channel)
        self._counts[cid] = 0
        return cid

    # -- messages

    def write_batch(self, batch: pl.DataFrame) -> None:
        """Write messages: columns ``channel`` (UInt16), ``log_time`` (UInt64 ns), ``data``.

        ``data`` is String (written as UTF-8) or Binary. Publish time is the log time. The
        batch is sorted by log time (stable) and cut into chunks by a worker thread while
        the caller goes on; its channels must be declared already.
        """
        if not batch.height:
            return
        first = self._sequence
        self._sequence += batch.height
        self._submit(batch, first)

    def write_lazy(self, batch: pl.LazyFrame | Callable[[], pl.DataFrame], height: int) -> None:
        """Like :meth:`write_batch`, the batch computed by the worker thread.

        Args:
            batch: a query, or a function, giving the columns of :meth:`write_batch`.
            height: the rows it gives (its messages' sequence numbers are given here).
        """
        if not height:
            return
        first = self._sequence
        self._sequence += height
        self._submit(batch, first)

    def _submit(self, batch: _Batch, first: int) -> None:
        self._pending.append(self._pool.submit(self._build, batch, first))
        # Placed only by count, never by the threads' timing: the file's bytes do not vary.
        while len(self._pending) > _IN_FLIGHT:
            self._place(self._pending.popleft().result())

    def _build(self, batch: _Batch, first: int) -> list[_Packed]:
        import polars as pl

        if isinstance(batch, pl.LazyFrame):
            batch = batch.collect()
        elif callable(batch):
            batch = batch()
        compressor = getattr(self._local, "zstd", None)
        if compressor is None:
            compressor = self._local.zstd = self._zstandard.ZstdCompressor(level=self._level)
        packed = []
        for chunk in build_chunks(batch, first, self._chunk_size, self._numpy):
            info = ChunkInfo(chunk.start, chunk.end, uncompressed=len(chunk.records))
            data = compressor.compress(chunk.records)
            crc = zlib.crc32(chunk.records)
            packed.append(_Packed(info, crc, chunk.indexes, chunk.counts, data))
        return packed

    def _place(self, chunks: list[_Packed]) -> None:
        for chunk in chunks:
            info = chunk.info
            self._start = info.start if self._start is None else min(self._start, info.start)
            self._end = max(self._end, info.end)
            content = (
                struct.pack("<QQQI", info.start, info.end, info.uncompressed, chunk.crc)
                + string("zstd")
                + struct.pack("<Q", len(chunk.data))
            )
            info.offset = self._pos
            info.compressed = len(chunk.data)
            self._write(PREFIX.pack(OP_CHUNK, len(content) + len(chunk.data)) + content)
            self._write(chunk.data)
            info.length = self._pos - info.offset
            index_start = self._pos
            for cid, index in chunk.indexes.items():
                info.index_offsets[cid] = self._pos
                self._write(index)
                self._counts[cid] += chunk.counts[cid]
            info.index_length = self._pos - index_start
            self._chunks.append(info)

    # -- the end

    def finish(self) -> None:
        """Write the remaining chunks, the summary and the footer."""
        if self._finished:
            return
        try:
            while self._pending:
                self._place(self._pending.popleft().result())
        finally:
            self._pool.shutdown(wait=True, cancel_futures=True)
        self._finished = True
        self._write(record(OP_DATA_END, struct.pack("<I", 0)))
        summary_start = self._pos
        groups: list[tuple[int, bytes]] = [
            (OP_SCHEMA, b"".join(self._schemas)),
            (OP_CHANNEL, b"".join(self._channels)),
            (
                OP_STATISTICS,
                statistics(
                    self._counts,
                    len(self._schemas),
                    len(self._channels),
                    len(self._chunks),
                    self._start or 0,
                    self._end,
                ),
            ),
            (OP_CHUNK_INDEX, b"".join(map(chunk_index, self._chunks))),
        ]
        summary = bytearray()
        offsets = bytearray()
        for opcode, data in groups:
            if data:
                offsets += record(
                    OP_SUMMARY_OFFSET,
                    struct.pack("<BQQ", opcode, summary_start + len(summary), len(data)),
                )
                summary += data
        offsets_start = summary_start + len(summary)
        footer_head = PREFIX.pack(OP_FOOTER, 20) + struct.pack("<QQ", summary_start, offsets_start)
        crc = zlib.crc32(bytes(summary) + bytes(offsets) + footer_head)
        self._write(bytes(summary) + bytes(offsets) + footer_head + struct.pack("<I", crc) + MAGIC)

    def abort(self) -> None:
        """Stop the worker threads without completing the file (an error upstream)."""
        self._finished = True
        self._pool.shutdown(wait=True, cancel_futures=True)

    @property
    def messages(self) -> int:
        """Messages written so far."""
        return self._sequence
