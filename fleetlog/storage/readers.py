r"""Reading session logs back: plain, gzip and zstd alogs, truncated tails, binary payloads.

This is the only layer that opens log files for reading. The format rules live in
:mod:`fleetlog.moos.alog`; this module adds the files around them:

* :func:`open_text` streams a ``.alog``, ``.alog.gz``, ``.alog.zst`` (or ``.xlog*``) as text,
  decompressing as it goes and stopping quietly where a crashed recorder's stream was cut.
* :class:`AlogReader` parses the banner and yields entries, or ``(absolute time, entry)``
  records, with the error policy chosen by the caller (``"raise"`` or ``"skip"``), and
  resolves binary values against the ``.blog`` beside the alog.
* :func:`sorted_window` and :func:`merge_records` put records from one or several vehicles
  in time order without loading them, for replay.

Text is decoded as UTF-8 with ``errors="surrogateescape"``, so any byte a value held survives
(``str.encode("utf-8", "surrogateescape")`` gives it back), and lines are split at ``\n``
only, so a ``\r`` inside a value stays in it.
"""

from __future__ import annotations

import heapq
import io
import os
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, BinaryIO, Generic, Literal, NamedTuple, Protocol, TypeVar

import zstandard

from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.moos.alog import (
    BANNER_RULE,
    Banner,
    BinaryRef,
    Entry,
    EntryParser,
    iter_entries,
    parse_banner,
)

if TYPE_CHECKING:
    from typing import Self

    from _typeshed import WriteableBuffer

__all__ = [
    "AlogReader",
    "Errors",
    "IndexedRecord",
    "LogText",
    "Record",
    "RecordMerge",
    "SortedWindow",
    "find_alog",
    "merge_records",
    "open_text",
    "sorted_window",
]

#: Compressed bytes read from the file at a time.
_READ_SIZE = 16 * 1024
#: zstd input fed at a time: zstandard's decompressobj has no output limit, so a small input
#: step keeps one decompressed piece small (a zstd block, at most 128 KiB, or the step times
#: the compression ratio).
_ZSTD_STEP = 8 * 1024
#: Largest piece of decompressed gzip output held at once.
_MAX_PIECE = 32 * 1024
_GZIP_WBITS = 16 + zlib.MAX_WBITS
#: A banner has 5 or 6 lines; give up looking for its closing line after this many.
_MAX_BANNER_LINES = 16
_BINARY_RECORD_END = 0x0A

#: The error policy of :class:`AlogReader`: ``"raise"`` (tests, tools) or ``"skip"`` (field logs).
Errors = Literal["raise", "skip"]


# --------------------------------------------------------------------------------------------
# Byte layer: streaming decompression that tolerates a cut tail


class _StreamState:
    """What the byte layer learned about the stream, read by :class:`LogText`."""

    __slots__ = ("compression", "truncated")

    def __init__(self, compression: str) -> None:
        self.compression = compression
        self.truncated = False


def _gzip_pieces(file: BinaryIO, path: Path, state: _StreamState) -> Iterator[bytes]:
    """Yield the decompressed bytes of a gzip file, member after member.

    A stream that ends inside a member (a crash: pLogger sync-flushes every 2048 bytes but
    writes the trailer only on a clean shutdown) yields what zlib could decode and sets
    ``state.truncated``. NUL padding after a member is ignored, as gzip(1) does.
    """
    member: zlib._Decompress | None = None
    consumed = 0
    while data := file.read(_READ_SIZE):
        consumed += len(data)
        while data:
            if member is None:
                data = data.lstrip(b"\x00")
                if not data:
                    break
                member = zlib.decompressobj(_GZIP_WBITS)
            try:
                piece = member.decompress(data, _MAX_PIECE)
            except zlib.error as err:
                msg = f"{path}: corrupt gzip data in the first {consumed} bytes: {err}"
                raise StorageError(msg) from err
            if piece:
                yield piece
            if member.eof:
                data = member.unused_data
                member = None
            else:
                data = member.unconsumed_tail
    if member is not None:
        try:
            piece = member.flush()
        except zlib.error:  # pragma: no cover - zlib returns what it has for a cut stream
            piece = b""
        if piece:
            yield piece
        state.truncated = not member.eof


def _zstd_pieces(file: BinaryIO, path: Path, state: _StreamState) -> Iterator[bytes]:
    """Yield the decompressed bytes of a zstd file, frame after frame.

    fleetlog's recorder writes a sequence of frames, closing one at least once a second. A
    stream that ends inside a frame yields the blocks that were complete and sets
    ``state.truncated``; one that ends between frames is whole.
    """
    context = zstandard.ZstdDecompressor()
    frame: zstandard.ZstdDecompressionObj | None = None
    consumed = 0
    while data := file.read(_ZSTD_STEP):
        consumed += len(data)
        while data:
            if frame is None:
                frame = context.decompressobj()
            try:
                piece = frame.decompress(data)
            except zstandard.ZstdError as err:
                msg = f"{path}: corrupt zstd data in the first {consumed} bytes: {err}"
                raise StorageError(msg) from err
            if piece:
                yield piece
            if frame.eof:
                data = frame.unused_data
                frame = None
            else:
                data = b""
    state.truncated = frame is not None


class _PieceReader(io.RawIOBase):
    """A raw binary stream over an iterator of byte pieces (the decompressor's output)."""

    def __init__(self, file: BinaryIO, pieces: Iterator[bytes]) -> None:
        super().__init__()
        self._file = file
        self._pieces = pieces
        self._pending = memoryview(b"")

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: WriteableBuffer) -> int:
        while not self._pending:
            piece = next(self._pieces, None)
            if piece is None:
                return 0
            self._pending = memoryview(piece)
        target = memoryview(buffer).cast("B")
        size = min(len(target), len(self._pending))
        target[:size] = self._pending[:size]
        self._pending = self._pending[size:]
        return size

    def close(self) -> None:
        if not self.closed:
            self._pending = memoryview(b"")
            close = getattr(self._pieces, "close", None)
            if close is not None:
                close()
            self._file.close()
        super().close()


class LogText(io.TextIOWrapper):
    r"""A log file opened for reading as text; what :func:`open_text` returns.

    Iterating yields lines ending in ``\n`` (the last may lack it when the file was cut).

    Attributes:
        path: the file.
        compression: ``""``, ``"gzip"`` or ``"zstd"``.
    """

    def __init__(self, raw: io.RawIOBase, path: Path, state: _StreamState) -> None:
        super().__init__(
            io.BufferedReader(raw),
            encoding="utf-8",
            errors="surrogateescape",
            newline="\n",
        )
        self.path = path
        self.compression = state.compression
        self._state = state

    @property
    def truncated(self) -> bool:
        """Whether the stream ended inside a gzip member or zstd frame (known at its end).

        An empty compressed file (no member or frame at all) is whole and empty. Always False
        for an uncompressed file: whether its last line was cut is for the line reader to see.
        """
        return self._state.truncated


def _compression_of(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return "gzip"
    if suffix == ".zst":
        return "zstd"
    return ""


def open_text(path: str | os.PathLike[str]) -> LogText:
    r"""Open a log file for streaming reading as text, decompressing by its suffix.

    ``.gz`` is read as gzip (one or more members), ``.zst`` as zstd (one or more frames),
    anything else as plain text. Decompression is incremental: memory does not grow with the
    file. A compressed stream cut short (a recorder that crashed) yields everything decodable
    up to the cut and then ends; :attr:`LogText.truncated` says so afterwards.

    The text is UTF-8 decoded with ``errors="surrogateescape"``, and lines are split at
    ``\n`` only (``newline="\n"``): ``\r`` is kept untranslated inside lines. (``newline=""``
    would keep it too, but would also end a line at every ``\r``, splitting values.)

    Args:
        path: the file.

    Returns:
        The open text stream; close it, or use it in a ``with`` block.

    Raises:
        StorageError: the file cannot be opened. Reading raises it too when compressed data
            is corrupt (as opposed to cut short).
    """
    file_path = Path(path)
    compression = _compression_of(file_path)
    state = _StreamState(compression)
    try:
        file = io.FileIO(file_path, "r")
    except OSError as err:
        msg = f"cannot open {file_path}: {err.strerror or err}"
        raise StorageError(msg) from err
    raw: io.RawIOBase
    if compression == "gzip":
        raw = _PieceReader(file, _gzip_pieces(file, file_path, state))
    elif compression == "zstd":
        raw = _PieceReader(file, _zstd_pieces(file, file_path, state))
    else:
        raw = file
    return LogText(raw, file_path, state)


# --------------------------------------------------------------------------------------------
# Records


class Record(NamedTuple):
    """An entry with its absolute time (``LOGSTART + offset``)."""

    time: float
    entry: Entry


class IndexedRecord(NamedTuple):
    """A record from a merge, tagged with the index of the input it came from (``origin``)."""

    time: float
    origin: int
    entry: Entry


class _Timed(Protocol):
    @property
    def time(self) -> float: ...


R = TypeVar("R", bound=_Timed)


def _time_of(record: _Timed) -> float:
    return record.time


# --------------------------------------------------------------------------------------------
# The alog reader


def _log_kind(path: Path) -> str:
    """Return ``".alog"``, ``".xlog"`` or another suffix, ignoring a compression suffix."""
    name = path.name
    if _compression_of(path):
        name = name[: -len(path.suffix)]
    return Path(name).suffix.lower()


class AlogReader:
    r"""Reads one ``.alog`` (or ``.xlog``), plain or compressed, as a stream of entries.

    The banner is read when the reader is created; :meth:`entries` and :meth:`records` then
    stream the entries without holding the file in memory. Each call starts a new pass over
    the file.

    Error policy (``errors``):

    * ``"raise"``: a missing or garbled banner raises :class:`FormatError` naming the file and
      line, as do lines after the banner that are neither entries nor comments; corrupt
      compressed data raises :class:`StorageError`.
    * ``"skip"``: each of those is counted in :attr:`skipped` instead. With no usable banner,
      :attr:`logstart` is None (entries still read; records need LOGSTART).

    Either way a cut tail is expected, not an error: the entries before the cut are yielded,
    an entry whose value may be cut short is not, and :attr:`truncated` is set. An ``.xlog``
    needs no banner (pLogger writes none when uncompressed, §4.2).

    Attributes:
        path: the file.
        errors: the error policy.
        banner: the parsed banner, or None (missing, garbled and skipped, or cut off).
        banner_error: why the banner could not be used, if it could not.
        truncated: the file was cut: the compressed stream ended early, the last line has no
            ``\n``, or the last entry lacks its terminator. Set by the banner read and by the
            end of each pass.
        skipped: problems skipped under ``errors="skip"`` in the latest pass: a bad banner,
            each stray line before the first entry, a corrupt compressed tail.

    Raises:
        StorageError: the file cannot be opened.
        FormatError: (``errors="raise"``) the banner is missing or garbled.
    """

    def __init__(self, path: str | os.PathLike[str], *, errors: Errors = "raise") -> None:
        if errors not in ("raise", "skip"):
            msg = f"errors must be 'raise' or 'skip', not {errors!r}"
            raise UsageError(msg)
        self.path = Path(path)
        self.errors: Errors = errors
        self.banner: Banner | None = None
        self.banner_error: FormatError | None = None
        self.truncated = False
        self.skipped = 0
        self._banner_skipped = 0
        self._open: set[LogText] = set()
        self._closed = False
        self._fresh: LogText | None = open_text(self.path)
        self._open.add(self._fresh)
        try:
            self._head = self._read_banner(self._fresh)
        except BaseException:
            self.close()
            raise

    # -- context management

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close the file (every pass still open over it)."""
        for stream in list(self._open):
            stream.close()
        self._open.clear()
        self._fresh = None
        self._closed = True

    # -- banner

    @property
    def logstart(self) -> float | None:
        """The banner's LOGSTART, or None without a usable banner."""
        return None if self.banner is None else self.banner.logstart

    def _read_banner(self, stream: LogText) -> list[str]:
        """Read and parse the banner; return the lines consumed, for the first pass."""
        head: list[str] = []
        xlog = _log_kind(self.path) == ".xlog"
        first = self._banner_line(stream, head)
        if first is None:
            return head
        body = first.removesuffix("\n")
        if body != BANNER_RULE:
            if not first.endswith("\n") and BANNER_RULE.startswith(body):
                # Empty, or cut inside the first line: the banner was never written whole.
                # (An empty xlog is just empty: it has no banner to lose.)
                self.truncated = bool(first) or stream.truncated or not xlog
            elif not xlog:  # an xlog has no banner when uncompressed (§4.2)
                reason = f"expected a banner line of 59 '%', got {body[:40]!r}"
                self._bad_banner(FormatError(reason, str(self.path), 1))
            return head
        while len(head) < _MAX_BANNER_LINES:
            line = self._banner_line(stream, head)
            if line is None:
                return head
            if not line.endswith("\n"):
                self.truncated = True  # the file ends inside its banner
                return head
            if line == BANNER_RULE + "\n" or not line.startswith("%"):
                break
        try:
            self.banner = parse_banner([line.removesuffix("\n") for line in head], str(self.path))
        except FormatError as err:
            self._bad_banner(err)
        return head

    def _banner_line(self, stream: LogText, head: list[str]) -> str | None:
        """Read one banner line into ``head``; None if the stream is corrupt (and skipped)."""
        try:
            line = stream.readline()
        except StorageError:
            if self.errors == "raise":
                raise
            self._banner_skipped += 1
            self.skipped = self._banner_skipped
            self.truncated = True
            return None
        if line:
            head.append(line)
        return line

    def _bad_banner(self, err: FormatError) -> None:
        if self.errors == "raise":
            raise err
        self.banner_error = err
        self._banner_skipped += 1
        self.skipped = self._banner_skipped

    def _corrupt(self, err: StorageError) -> None:
        if self.errors == "raise":
            raise err
        self.skipped += 1
        self.truncated = True

    # -- entries

    def _lines(self, stream: LogText, head: list[str]) -> Iterator[str]:
        """Yield the pass's lines, then mark a cut the line layer cannot see."""
        yield from head
        last = head[-1] if head else ""
        cut = False
        try:
            for line in stream:
                if not line.endswith("\n"):
                    # The last line, cut: iter_entries stops at it, so note the cut now.
                    self.truncated = True
                yield line
                last = line
        except StorageError as err:
            self._corrupt(err)
            cut = True
        except OSError as err:
            msg = f"cannot read {self.path}: {err.strerror or err}"
            raise StorageError(msg) from err
        except ValueError as err:  # I/O on the closed file
            if not stream.closed:
                raise
            msg = f"{self.path}: the reader was closed during a pass"
            raise StorageError(msg) from err
        if cut or stream.truncated:
            self.truncated = True
            if not last or last.endswith("\n"):
                # Cut right after a newline: the entry before may have lost continuation
                # lines, so pass an empty cut line to drop it (see iter_entries). It is the
                # last line: iter_entries stops there, nothing after this yield runs.
                yield ""

    def entries(self) -> Iterator[Entry]:
        """Yield the file's entries in file order (not time order, see §2.2).

        Raises:
            StorageError: the file cannot be read, or (``errors="raise"``) its compressed
                data is corrupt.
            FormatError: (``errors="raise"``) lines after the banner are neither entries nor
                comments.
        """
        if self._closed:
            msg = f"{self.path}: the reader is closed"
            raise StorageError(msg)
        if self._fresh is not None:
            stream, head = self._fresh, self._head
            self._fresh = None
        else:
            stream, head = open_text(self.path), []
            self._open.add(stream)
            self.truncated = False
        self.skipped = self._banner_skipped
        return self._entries(stream, head)

    def _entries(self, stream: LogText, head: list[str]) -> Iterator[Entry]:
        mark = self.banner is not None and self.banner.mark_data_type
        parser = EntryParser(mark_data_type=mark)
        counted = 0
        try:
            for entry in iter_entries(self._lines(stream, head), parser=parser):
                counted = self._check_orphans(parser, counted, entry.lineno)
                yield entry
            self._check_orphans(parser, counted, None)
            if parser.dropped:
                self.truncated = True
        finally:
            stream.close()
            self._open.discard(stream)

    def _check_orphans(self, parser: EntryParser, counted: int, lineno: int | None) -> int:
        if parser.orphans == counted:
            return counted
        if self.errors == "raise":
            where = f"before line {lineno}" if lineno is not None else "after the banner"
            msg = f"{parser.orphans} line(s) {where} are neither entries nor comments"
            raise FormatError(msg, str(self.path), lineno)
        self.skipped += parser.orphans - counted
        return parser.orphans

    def records(self) -> Iterator[Record]:
        """Yield ``(absolute_time, entry)`` records in file order; time is LOGSTART + offset.

        Raises:
            StorageError: the file has no usable banner, so absolute times are unknown; or
                as :meth:`entries`.
        """
        logstart = self.logstart
        if logstart is None:
            why = (
                "was cut off" if self.banner_error is None else f"is unusable ({self.banner_error})"
            )
            msg = f"{self.path}: no LOGSTART (the banner {why}), so absolute times are unknown"
            raise StorageError(msg)
        return (Record(logstart + entry.offset, entry) for entry in self.entries())

    # -- binary payloads

    @property
    def blog_path(self) -> Path:
        """The ``.blog`` beside this log (``root.blog`` for ``root.alog[.gz|.zst]``)."""
        name = self.path.name
        if _compression_of(self.path):
            name = name[: -len(self.path.suffix)]
        return self.path.with_name(Path(name).with_suffix(".blog").name)

    def read_binary(self, entry: Entry) -> bytes:
        """Return the payload of a binary entry from the ``.blog`` its reference names.

        ``File=`` is a bare file name, relative to this log's directory (§2.6).

        Raises:
            StorageError: the entry is not binary, its reference is unusable (``Offset=-1``
                after a pLogger restart, a path outside the directory, a range past the end
                of the blog or not ending a blog record), or the blog cannot be read. The
                message names the log line, the blog and the offset.
        """
        ref = entry.value
        where = f"{self.path}:{entry.lineno}: {entry.key}"
        if not isinstance(ref, BinaryRef):
            msg = f"{where} is not a binary value"
            raise StorageError(msg)
        if not ref.file or ref.file in (".", "..") or Path(ref.file).name != ref.file:
            msg = f"{where} refers to {ref.file!r}, which is not a file beside the log"
            raise StorageError(msg)
        blog = self.path.parent / ref.file
        if ref.offset < 0:
            msg = (
                f"{where} has no payload: {ref.file} Offset={ref.offset} (pLogger did not"
                " reopen its blog after LOGGER_RESTART, so the bytes were never written)"
            )
            raise StorageError(msg)
        try:
            with blog.open("rb") as file:
                file.seek(ref.offset)
                data = file.read(ref.size + 1)
        except OSError as err:
            msg = f"{where}: cannot read {blog} at Offset={ref.offset}: {err.strerror or err}"
            raise StorageError(msg) from err
        if len(data) < ref.size:
            msg = (
                f"{where}: {blog} ends before Offset={ref.offset} + Bytes={ref.size}"
                f" ({len(data)} bytes there)"
            )
            raise StorageError(msg)
        if len(data) > ref.size and data[ref.size] != _BINARY_RECORD_END:
            msg = (
                f"{where}: {blog} at Offset={ref.offset}, Bytes={ref.size} is not a blog"
                " record (the payload is not followed by a newline)"
            )
            raise StorageError(msg)
        return data[: ref.size]


# --------------------------------------------------------------------------------------------
# Time order


class SortedWindow(Generic[R]):
    """A streaming re-sort by time with a bounded buffer (what alogsort does with 1000 lines).

    Records are held in a heap of at most ``window`` records; once it is full, each new record
    pushes out the earliest one. A record that arrives after a later one has already left the
    window (it is out of place by more than ``window`` records) cannot be put back: it is
    yielded late, as soon as possible, and counted in :attr:`late`. Records with equal times
    keep their input order.

    Attributes:
        window: the buffer size.
        late: records yielded after a record with a later time.

    Raises:
        UsageError: ``window`` is negative.
    """

    def __init__(
        self, records: Iterable[R], window: int = 1000, *, key: Callable[[R], float] | None = None
    ) -> None:
        if window < 0:
            msg = f"the sort window must be 0 or more records, not {window}"
            raise UsageError(msg)
        self.window = window
        self.late = 0
        self._key: Callable[[R], float] = key if key is not None else _time_of
        self._run = self._sort(records)

    def __iter__(self) -> Self:
        return self

    def __next__(self) -> R:
        return next(self._run)

    def _sort(self, records: Iterable[R]) -> Iterator[R]:
        heap: list[tuple[float, int, R]] = []
        key = self._key
        last = -float("inf")
        for seq, record in enumerate(records):
            heapq.heappush(heap, (key(record), seq, record))
            if len(heap) > self.window:
                when, _, out = heapq.heappop(heap)
                if when < last:
                    self.late += 1
                else:
                    last = when
                yield out
        while heap:
            when, _, out = heapq.heappop(heap)
            if when < last:
                self.late += 1
            else:
                last = when
            yield out


def sorted_window(
    records: Iterable[R], window: int = 1000, *, key: Callable[[R], float] | None = None
) -> SortedWindow[R]:
    """Re-sort ``records`` by time in a bounded window; see :class:`SortedWindow`.

    alogs are not globally time-sorted (§2.2: mail batches are sorted, the file is in arrival
    order, and re-delivered values re-appear with their old times). A window of 1000 records
    puts ordinary files in order; a record displaced by more than that is yielded late and
    counted in the returned iterator's ``late``.

    Args:
        records: the records, usually :meth:`AlogReader.records`.
        window: how many records to hold back at most.
        key: the time of a record; ``record.time`` by default.

    Returns:
        An iterator over the records, with a ``late`` count.

    Raises:
        UsageError: ``window`` is negative.
    """
    return SortedWindow(records, window, key=key)


class RecordMerge:
    """The iterator :func:`merge_records` returns.

    Attributes:
        windows: each input's re-sort window, in input order (empty without windows).
    """

    def __init__(
        self,
        inputs: Sequence[Iterable[Record]],
        key: Callable[[IndexedRecord], float],
        window: int | None,
    ) -> None:
        tagged = [_tag(records, index) for index, records in enumerate(inputs)]
        self.windows: list[SortedWindow[IndexedRecord]] = []
        streams: list[Iterable[IndexedRecord]] = list(tagged)
        if window is not None:
            self.windows = [SortedWindow(stream, window, key=key) for stream in tagged]
            streams = list(self.windows)
        self._merged = heapq.merge(*streams, key=key)

    @property
    def late(self) -> int:
        """Records that left their input's window out of order (see :class:`SortedWindow`)."""
        return sum(window.late for window in self.windows)

    def __iter__(self) -> Self:
        return self

    def __next__(self) -> IndexedRecord:
        return next(self._merged)


def _tag(records: Iterable[Record], index: int) -> Iterator[IndexedRecord]:
    for time, entry in records:
        yield IndexedRecord(time, index, entry)


def merge_records(
    sources: Sequence[AlogReader | Iterable[Record]],
    *,
    key: Callable[[IndexedRecord], float] | None = None,
    window: int | None = 1000,
) -> RecordMerge:
    """Merge several logs' records into one stream by absolute time (multi-vehicle replay).

    Each input is first re-sorted in a bounded window (:func:`sorted_window`), because a
    single alog is not time-sorted; then the inputs are merged with :func:`heapq.merge`.
    Each record is tagged with the index of its input. Records with equal times come in
    input order, and within an input in file order.

    Args:
        sources: readers (their :meth:`AlogReader.records` are used) or record iterables.
        key: the time to order by; the absolute time by default.
        window: each input's re-sort window in records; None merges the inputs as they come
            (only right for inputs that are already sorted).

    Returns:
        An iterator of :class:`IndexedRecord`, with a ``late`` count of records that were out
        of order by more than the window.

    Raises:
        StorageError: a reader has no LOGSTART, or as :meth:`AlogReader.records`.
        UsageError: ``window`` is negative.
    """
    inputs = [src.records() if isinstance(src, AlogReader) else src for src in sources]
    return RecordMerge(inputs, key if key is not None else _time_of, window)


# --------------------------------------------------------------------------------------------
# Sessions

_ALOG_SUFFIXES = (".alog", ".alog.zst", ".alog.gz")


def find_alog(session_dir: str | os.PathLike[str]) -> Path:
    """Return the alog of a session directory: ``.alog``, ``.alog.zst`` or ``.alog.gz``.

    The one named after the directory (``root/root.alog``) is preferred, in that suffix
    order; otherwise the directory must hold exactly one alog.

    Raises:
        StorageError: the directory cannot be listed, holds no alog, or holds several and
            none is named after it.
    """
    directory = Path(session_dir)
    for suffix in _ALOG_SUFFIXES:
        named = directory / (directory.name + suffix)
        if named.is_file():
            return named
    try:
        found = sorted(
            child
            for child in directory.iterdir()
            if child.name.endswith(_ALOG_SUFFIXES) and child.is_file()
        )
    except OSError as err:
        msg = f"cannot list session directory {directory}: {err.strerror or err}"
        raise StorageError(msg) from err
    if not found:
        msg = f"{directory} holds no .alog, .alog.zst or .alog.gz"
        raise StorageError(msg)
    if len(found) > 1:
        names = ", ".join(child.name for child in found)
        msg = f"{directory} holds several alogs and none is named after it: {names}"
        raise StorageError(msg)
    return found[0]
