"""A batch of messages as MCAP chunks: sorted by time, cut by size, indexed, assembled.

A batch (columns ``channel``, ``log_time``, ``data``) is sorted by log time (stable; skipped
when it is sorted already, the common case), cut into chunks of about ``chunk_size``
uncompressed bytes, and each chunk's Message records are assembled into one buffer with its
Message Index records (per channel, in channel order, (log time, offset) in time order).

Two ways to assemble, giving the same bytes (a test holds it):

* with numpy (an optional accelerator): headers written as one structured array, each
  joined to its message's data by polars (a Binary ``+``), and the records laid end to end
  by exploding them as lists of bytes (copies in Rust, not masked numpy assignments), one
  chunk at a time as the writer takes them (still in the cache when it compresses them);
  the indexes are a stable argsort of each chunk's channels. No Python object per message.
* without it: the headers packed by one precompiled :class:`struct.Struct` mapped over the
  batch and joined with the data (a loop in C, still a few Python objects per message).

Chunks are built here, in a worker thread of :class:`~fleetlog.export.mcapfile.McapWriter`;
compressing and placing them in the file is the writer's.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import chain, pairwise, repeat
from typing import TYPE_CHECKING, Any

from fleetlog.export.mcaprecords import MESSAGE_FIXED, OP_MESSAGE, message_index

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Chunk", "build_chunks"]

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log and publish time
_RECORD_FIXED = MESSAGE_FIXED + 9  # a message record's bytes before its data
#: The message record's fixed part as a numpy structured type (packed, like _MESSAGE).
_HEADER_FIELDS = [
    ("op", "u1"),
    ("length", "<u8"),
    ("channel", "<u2"),
    ("sequence", "<u4"),
    ("log_time", "<u8"),
    ("publish_time", "<u8"),
]


@dataclass
class Chunk:
    """One chunk's uncompressed records and its message indexes.

    Attributes:
        start: the earliest log time in it.
        end: the latest.
        records: its Message records, back to back.
        indexes: the Message Index record of each channel in it, in channel order.
        counts: messages per channel.
    """

    start: int
    end: int
    records: bytes | memoryview
    indexes: dict[int, bytes]
    counts: dict[int, int]


def _prepared(batch: pl.DataFrame) -> pl.DataFrame:
    import polars as pl

    frame = batch.select(
        pl.col("channel").cast(pl.UInt16),
        pl.col("log_time").cast(pl.UInt64),
        pl.col("data").cast(pl.Binary).fill_null(b""),  # no data: an empty message
    )
    if not frame["log_time"].is_sorted():
        frame = frame.sort("log_time", maintain_order=True)
    return frame


def build_chunks(batch: pl.DataFrame, first: int, chunk_size: int, numpy: Any) -> Iterator[Chunk]:
    """The batch's messages as chunks, one at a time (``numpy`` the module, or None).

    Args:
        batch: columns ``channel`` (UInt16), ``log_time`` (UInt64 ns), ``data`` (String or
            Binary); publish time is the log time.
        first: the sequence number of the batch's first message (in time order).
        chunk_size: uncompressed message bytes per chunk (a chunk ends after the message
            that crosses it).
        numpy: the numpy module to assemble with, or None.
    """
    frame = _prepared(batch)
    if numpy is not None and _casts_bytes():
        return _with_numpy(frame, first, chunk_size, numpy)
    return iter(_pure(frame, first, chunk_size))


@functools.cache
def _casts_bytes() -> bool:
    """Whether polars casts a list of bytes to Binary (1.30 and later), as _records needs."""
    import polars as pl

    try:
        pl.Series([[1]], dtype=pl.List(pl.UInt8)).cast(pl.Binary)
    except pl.exceptions.InvalidOperationError:
        return False
    return True


def _heads(heads: Any, np: Any) -> pl.Series:
    """The headers (a numpy structured array) as a Binary column."""
    import polars as pl

    fixed = pl.Series(heads.view(np.uint8).reshape(len(heads), _RECORD_FIXED))
    return fixed.cast(pl.List(pl.UInt8)).cast(pl.Binary)


def _records(data: pl.Series, fixed: pl.Series) -> Any:
    """Every header followed by its message's data, end to end, as one numpy byte array."""
    import polars as pl

    # One chunk (cheap for views), so that the exploded bytes are the list's own buffer.
    records = fixed + data.rechunk()
    # A record is never empty (its header), so the exploded bytes are all of them, in order.
    return records.cast(pl.List(pl.UInt8)).explode().to_numpy()


def _with_numpy(frame: pl.DataFrame, first: int, chunk_size: int, np: Any) -> Iterator[Chunk]:
    n = frame.height
    data = frame["data"]
    size = data.bin.size().to_numpy().astype(np.int64) + _RECORD_FIXED
    at = np.cumsum(size) - size
    channels = frame["channel"].to_numpy()
    times = frame["log_time"].to_numpy()
    heads = np.zeros(n, dtype=np.dtype(_HEADER_FIELDS))
    heads["op"] = OP_MESSAGE
    heads["length"] = size - 9
    heads["channel"] = channels
    heads["sequence"] = np.arange(first, first + n, dtype="<u8") & 0xFFFFFFFF
    heads["log_time"] = times
    heads["publish_time"] = times
    fixed = _heads(heads, np)
    part = at // chunk_size
    bounds = [0, *(np.flatnonzero(part[1:] != part[:-1]) + 1).tolist(), n]
    for lo, hi in pairwise(bounds):
        # Each chunk's records are made when it is wanted (about 1 MiB, still in the cache
        # when the caller compresses and checksums them), not the whole batch's at once.
        out = _records(data.slice(lo, hi - lo), fixed.slice(lo, hi - lo))
        begin = int(at[lo])
        mine = channels[lo:hi]
        order = np.argsort(mine, kind="stable")
        pairs = np.empty((hi - lo, 2), dtype="<u8")
        pairs[:, 0] = times[lo:hi][order]
        pairs[:, 1] = (at[lo:hi] - begin)[order]
        cids, starts, counts = np.unique(mine[order], return_index=True, return_counts=True)
        indexes: dict[int, bytes] = {}
        per_channel: dict[int, int] = {}
        for cid, i, k in zip(cids.tolist(), starts.tolist(), counts.tolist(), strict=True):
            indexes[cid] = message_index(cid, pairs[i : i + k].tobytes())
            per_channel[cid] = k
        yield Chunk(int(times[lo]), int(times[hi - 1]), memoryview(out), indexes, per_channel)


def _pure(frame: pl.DataFrame, first: int, chunk_size: int) -> list[Chunk]:
    import polars as pl

    frame = (
        frame.with_columns(size=(pl.col("data").bin.size() + _RECORD_FIXED).cast(pl.UInt64))
        .with_columns(at=pl.col("size").cum_sum() - pl.col("size"))
        .with_columns(part=(pl.col("at") // chunk_size).rle_id())
        .with_columns(offset=pl.col("at") - pl.col("at").min().over("part"))
    )
    ordered = frame.select("part", "channel", "log_time", "offset").sort(
        "part", "channel", maintain_order=True
    )
    runs = ordered.group_by("part", "channel", maintain_order=True).len().rows()
    pairs = ordered.select(pl.concat_list("log_time", "offset").explode()).to_series().to_list()
    sizes = frame.group_by("part", maintain_order=True).agg(
        pl.len(), pl.col("log_time").first().alias("start"), pl.col("log_time").last()
    )
    channels = frame["channel"].to_list()
    times = frame["log_time"].to_list()
    datas = frame["data"].to_list()
    lengths = (frame["size"] - 9).to_list()  # a message record's content length
    chunks = []
    row = pair = run = 0
    for part, count, start, end in sizes.rows():
        indexes: dict[int, bytes] = {}
        per_channel: dict[int, int] = {}
        while run < len(runs) and runs[run][0] == part:
            _, cid, k = runs[run]
            run += 1
            values = pairs[2 * pair : 2 * (pair + k)]
            indexes[cid] = message_index(cid, struct.pack(f"<{2 * k}Q", *values))
            per_channel[cid] = k
            pair += k
        rows = slice(row, row + count)
        sequences = (s & 0xFFFFFFFF for s in range(first + row, first + row + count))
        # map() and join() run the per-message loop in C: no Python bytecode per message.
        heads = map(
            _MESSAGE.pack,
            repeat(OP_MESSAGE),
            lengths[rows],
            channels[rows],
            sequences,
            times[rows],
            times[rows],
        )
        records = b"".join(chain.from_iterable(zip(heads, datas[rows], strict=True)))
        chunks.append(Chunk(start, end, records, indexes, per_channel))
        row += count
    return chunks
