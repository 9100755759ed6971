r"""The columnar alog reader: the one read path under every consumer.

An alog (plain, ``.gz`` or ``.zst``; an ``.xlog`` too) is read in bounded blocks of bytes and
each block becomes a :mod:`polars` DataFrame of typed columns, so the per-line work runs in
vectorised Rust instead of a Python loop. Memory is bounded by the block size plus the
largest single entry, never by the file's size.

Each batch (:meth:`AlogReader.batches`) has these columns (see :data:`SCHEMA`):

========  ============  ==================================================================
line      Int64         the 1-based line where the entry starts
offset    Float64       seconds since LOGSTART, as written
time      Float64       LOGSTART + offset (null without a usable banner)
var       String        the variable
source    String        the source column as written: ``src[:aux][@community]``
src       String        the process name (before ``:`` and ``@``)
aux       String        the aux source (after ``:``; empty without one)
type      Enum          ``double``, ``string`` or ``binary``
double    Float64       the double value (null for strings and binary values)
text      String        the value as written, without padding, MarkDataType marker or
                        terminator space; for a binary value the ``<MOOS_BINARY>`` tag
raw       Binary        the entry's exact bytes (its lines, ``\n``-joined, without the last
                        ``\n``): what grep and clip write back
========  ============  ==================================================================

String columns are UTF-8. A log that holds bytes that are not UTF-8 gets U+FFFD for each
such byte in ``var``, ``source`` and ``text``; ``raw`` keeps the bytes, and
:meth:`AlogReader.entries` gives them back exactly (``surrogateescape``), as every fleetlog
reader always has.

The reading rules are MOOS_FORMAT.md §12's, the same as the line parser that came before
(kept in ``tests/alog_oracle.py``, against which property tests hold this one):

* an entry line starts with a time (a digit, or ``-`` and a digit), and its columns follow
  the writer's rule: each field left-justified to 15, 20 and 15 characters or wider, then
  one space; the value is everything after that, minus one terminator space;
* lines that are neither entries nor comments (``%``) continue the value before them; before
  any entry (or after a comment) they are stray lines (an error, or counted as skipped);
* the type comes from the ``D:``/``S:`` marker under ``%% DATATYPE MARKING ON``; without
  it, a value that is exactly a double as pLogger pads it is a double; a
  ``<MOOS_BINARY>...</MOOS_BINARY>`` tag without terminator space is binary, its bytes in
  the ``.blog`` (:meth:`AlogReader.read_binary`);
* a cut tail is expected: the entries before the cut are read, an entry whose value may be
  cut short is not, and :attr:`AlogReader.truncated` says so.

The library's thread pool is sized when polars is first imported; a recorder caps it with
:func:`limit_threads` before that, so that analysis never starves recording. polars is
imported on first use, so a process that never reads a log never loads it.

This module holds the reader (opening, the banner, what a pass yields, binary payloads);
the parts it is built from each have their own: :mod:`~fleetlog.storage.alogpass` (one
streaming pass over the blocks: cuts, workers, stray lines, the cut tail),
:mod:`~fleetlog.storage.columns` (the schema and polars),
:mod:`~fleetlog.storage.alogfields` (where a line's columns are),
:mod:`~fleetlog.storage.alogblocks` (a block becomes entries),
:mod:`~fleetlog.storage.alogtypes` (values become typed columns),
:mod:`~fleetlog.storage.batches` (a batch and its :class:`Entry` rows),
:mod:`~fleetlog.storage.alogtail` (the end of a log, resumed scans),
:mod:`~fleetlog.storage.blog` and :mod:`~fleetlog.storage.sessionalog`. What callers used from
here is still importable from here.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.moos.alog import BANNER_RULE, Banner, Entry, parse_banner
from fleetlog.storage.alogpass import BlockPasses
from fleetlog.storage.alogtail import parse_lines, read_tail
from fleetlog.storage.batches import Batch, to_entries
from fleetlog.storage.blog import blog_beside, read_payload
from fleetlog.storage.columns import (
    ALWAYS,
    SCHEMA,
    Errors,
    limit_threads,
)
from fleetlog.storage.decompress import LogBytes, compression_of, log_kind, open_bytes
from fleetlog.storage.ordering import Record
from fleetlog.storage.purity import PurityMemo
from fleetlog.storage.sessionalog import find_alog

if TYPE_CHECKING:
    from typing import Self

    import polars as pl

__all__ = [
    "BLOCK_SIZE",
    "SCHEMA",
    "AlogReader",
    "Batch",
    "Errors",
    "find_alog",
    "limit_threads",
    "parse_lines",
    "read_tail",
]

#: Decompressed bytes parsed at a time by default (about 50k lines of a typical log; with two
#: blocks in flight, 8 MiB blocks peaked at 366 MiB and 4 MiB at 258, at the same speed).
BLOCK_SIZE = 4 << 20
_MAX_BANNER_LINES = 16
#: Columns every pass computes: stray lines are placed by line, exact bytes by line count.
_COUNTED = frozenset(("line", "nlines"))


class AlogReader(BlockPasses):
    r"""Reads one ``.alog`` (or ``.xlog``), plain or compressed, as batches of typed columns.

    The banner is read when the reader is created; :meth:`batches`, :meth:`entries` and
    :meth:`records` then stream the file. Each call starts a new pass.

    Error policy (``errors``):

    * ``"raise"``: a missing or garbled banner raises :class:`FormatError` naming the file and
      line, as do lines after the banner that are neither entries nor comments; corrupt
      compressed data raises :class:`StorageError`.
    * ``"skip"``: each of those is counted in :attr:`skipped` instead. With no usable banner,
      :attr:`logstart` is None (entries still read; records need LOGSTART).

    Either way a cut tail is expected, not an error (see the module docstring). An ``.xlog``
    needs no banner (pLogger writes none when uncompressed, §4.2).

    Args:
        path: the file.
        errors: the error policy.
        block_size: decompressed bytes parsed at a time; smaller blocks hold the GIL for
            less time (a recorder's remote grep uses 1 MiB), larger ones are a little faster.
        purity: where a plain log's passes learn which of its ranges hold entry lines only,
            and where a selective pass (``where`` with literals) looks it up, to cut fewer
            lines (:mod:`fleetlog.storage.purity`); None: neither.

    Attributes:
        path: the file.
        errors: the error policy.
        banner: the parsed banner, or None (missing, garbled and skipped, or cut off).
        banner_error: why the banner could not be used, if it could not.
        truncated: the file was cut: the compressed stream ended early, the last line has no
            ``\n``, or the last entry lacks its terminator. Set by the banner read and by the
            end of each pass.
        skipped: problems skipped under ``errors="skip"`` in the latest pass: a bad banner,
            each stray line, a corrupt compressed tail.
        scanned: entries read in the latest pass so far (those a ``where`` dropped too).

    Raises:
        StorageError: the file cannot be opened.
        FormatError: (``errors="raise"``) the banner is missing or garbled.
        UsageError: an unknown error policy or a block size under 1 KiB.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        errors: Errors = "raise",
        block_size: int = BLOCK_SIZE,
        purity: PurityMemo | None = None,
    ) -> None:
        if errors not in ("raise", "skip"):
            msg = f"errors must be 'raise' or 'skip', not {errors!r}"
            raise UsageError(msg)
        if block_size < 1024:
            msg = f"block_size must be at least 1024 bytes, not {block_size}"
            raise UsageError(msg)
        self.path = Path(path)
        self.errors: Errors = errors
        self.block_size = block_size
        self.purity = purity
        self.banner: Banner | None = None
        self.banner_error: FormatError | None = None
        self.truncated = False
        self.skipped = 0
        self.scanned = 0
        self._banner_skipped = 0
        self._open: set[LogBytes] = set()
        self._closed = False
        self._fresh: LogBytes | None = open_bytes(self.path)
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

    @property
    def banner_bytes(self) -> bytes:
        """The banner exactly as written, newlines included (empty without a usable one)."""
        if self.banner is None:
            return b""
        lines = self._head.split(b"\n")[: self.banner.lines]
        return b"\n".join(lines) + b"\n"

    @property
    def compression(self) -> str:
        """``""``, ``"gzip"`` or ``"zstd"``."""
        return compression_of(self.path)

    def _read_banner(self, stream: LogBytes) -> bytes:
        """Read and parse the banner; return the bytes consumed, for the first pass."""
        head: list[bytes] = []
        xlog = log_kind(self.path) == ".xlog"
        first = self._banner_line(stream, head)
        if first is None:
            return b"".join(head)
        body = first.removesuffix(b"\n")
        rule = BANNER_RULE.encode()
        if body != rule:
            if not first.endswith(b"\n") and rule.startswith(body):
                # Empty, or cut inside the first line: the banner was never written whole.
                # (An empty xlog is just empty: it has no banner to lose.)
                self.truncated = bool(first) or stream.truncated or not xlog
            elif not xlog:  # an xlog has no banner when uncompressed (§4.2)
                text = body.decode("utf-8", "surrogateescape")
                reason = f"expected a banner line of 59 '%', got {text[:40]!r}"
                self._bad_banner(FormatError(reason, str(self.path), 1))
            return b"".join(head)
        while len(head) < _MAX_BANNER_LINES:
            line = self._banner_line(stream, head)
            if line is None:
                return b"".join(head)
            if not line.endswith(b"\n"):
                self.truncated = True  # cut inside the banner: no entries to read
                return b"".join(head)
            if line == rule + b"\n" or not line.startswith(b"%"):
                break
        lines = [line.decode("utf-8", "surrogateescape").removesuffix("\n") for line in head]
        try:
            self.banner = parse_banner(lines, str(self.path))
        except FormatError as err:
            self._bad_banner(err)
        return b"".join(head)

    def _banner_line(self, stream: LogBytes, head: list[bytes]) -> bytes | None:
        """Read one banner line into ``head``; None if the stream is corrupt (and skipped)."""
        try:
            line = stream.readline(self.block_size)
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

    # -- batches

    def batches(
        self,
        columns: Iterable[str] | None = None,
        where: Callable[[pl.DataFrame], pl.Series] | None = None,
    ) -> Iterator[pl.DataFrame]:
        """Yield the file's entries in file order (not time order, §2.2) as DataFrames.

        Args:
            columns: the columns wanted, of :data:`SCHEMA` (all by default). Asking for
                fewer is faster: ``src``/``aux``, ``time`` and ``raw`` are only computed
                when asked for. The batches have them in :data:`SCHEMA`'s order.
            where: a filter applied before the values are typed, faster than filtering the
                batches afterwards (grep, clip): it gets a DataFrame of the block's entries
                with ``line``, ``offset``, ``var`` and ``source`` and returns a Boolean
                Series of the rows to keep. :attr:`scanned` still counts every entry.

        Raises:
            StorageError: the file cannot be read, or (``errors="raise"``) its compressed
                data is corrupt.
            FormatError: (``errors="raise"``) lines after the banner are neither entries nor
                comments.
            UsageError: an unknown column.
        """
        order = self._order(columns)
        # Only the columns asked for (and what the reader itself reads): a batch of columns
        # has no entries() to serve, so the values a caller did not ask for are not typed.
        frames = self._frames(frozenset(order) | _COUNTED, where)
        return (frame.select(order) for frame, _ in frames)

    def frames(
        self,
        columns: Iterable[str] | None = None,
        where: Callable[[pl.DataFrame], pl.Series] | None = None,
    ) -> Iterator[Batch]:
        """Yield the file's entries as :class:`Batch` objects: :meth:`batches` plus exactness.

        For consumers that must give every byte back (grep's text, replay's values): a
        batch whose block was all UTF-8 is exact in its columns; otherwise its
        :meth:`Batch.entries` are. Arguments and errors as :meth:`batches`.
        """
        order = self._order(columns)
        frames = self._frames(frozenset(order) | ALWAYS, where)
        return (Batch(frame.select(order), exact, frame) for frame, exact in frames)

    @staticmethod
    def _order(columns: Iterable[str] | None) -> list[str]:
        """Return the columns asked for in SCHEMA's order; raise UsageError on unknown ones."""
        wanted = list(SCHEMA) if columns is None else list(columns)
        unknown = [name for name in wanted if name not in SCHEMA]
        if unknown:
            msg = f"unknown column(s) {', '.join(map(repr, unknown))}; known: {', '.join(SCHEMA)}"
            raise UsageError(msg)
        return [name for name in SCHEMA if name in wanted]

    def _frames(
        self,
        want: frozenset[str],
        where: Callable[[pl.DataFrame], pl.Series] | None = None,
    ) -> Iterator[tuple[pl.DataFrame, bool]]:
        if self._closed:
            msg = f"{self.path}: the reader is closed"
            raise StorageError(msg)
        if self._fresh is not None:
            stream, head = self._fresh, self._head
            self._fresh = None
        else:
            stream, head = open_bytes(self.path), b""
            self._open.add(stream)
            self.truncated = False
        self.skipped = self._banner_skipped
        self.scanned = 0
        return self._pass(stream, head, want, where)

    # -- entries and records

    def entries(self, where: Callable[[pl.DataFrame], pl.Series] | None = None) -> Iterator[Entry]:
        """Yield the file's entries as :class:`Entry` objects, in file order.

        ``where`` filters as in :meth:`batches`.

        Values are exact: a string that held bytes that are not UTF-8 gets them back as
        ``surrogateescape`` characters.

        Raises:
            StorageError: as :meth:`batches`.
            FormatError: as :meth:`batches`.
        """
        return self._entries(self._frames(ALWAYS, where))

    def _entries(self, frames: Iterator[tuple[pl.DataFrame, bool]]) -> Iterator[Entry]:
        try:
            for frame, exact in frames:
                yield from to_entries(frame, exact)
        finally:
            close = getattr(frames, "close", None)
            if close is not None:
                close()

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
        return blog_beside(self.path)

    def read_binary(self, entry: Entry) -> bytes:
        """Return the payload of a binary entry from the ``.blog`` its reference names.

        ``File=`` is a bare file name, relative to this log's directory (§2.6).

        Raises:
            StorageError: as :func:`fleetlog.storage.blog.read_payload`.
        """
        return read_payload(self.path, entry)
