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
"""

from __future__ import annotations

import codecs
import importlib
import os
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType, TracebackType
from typing import TYPE_CHECKING, Any, Literal

from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.moos.alog import (
    BANNER_RULE,
    DATATYPE_MARKING,
    Banner,
    BinaryRef,
    Entry,
    parse_banner,
    parse_binary_ref,
    split_source,
)
from fleetlog.storage.decompress import LogBytes, compression_of, log_kind, open_bytes
from fleetlog.storage.ordering import Record

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

#: Decompressed bytes parsed at a time by default (about 100k lines of a typical log).
BLOCK_SIZE = 8 << 20
#: Blocks parsed at once (never more than polars' thread pool: one in a recorder).
_WORKERS = 2
#: Lines looked at, from the end of a block, for an entry to cut the block before.
_CUT_LOOKBACK = 64
#: Rows turned into Entry objects at a time.
_ENTRY_CHUNK = 1024
#: The error policy: ``"raise"`` (tests, tools) or ``"skip"`` (field logs, remote grep).
Errors = Literal["raise", "skip"]

#: The columns of a batch and their types, in order (polars type names).
SCHEMA: dict[str, str] = {
    "line": "Int64",
    "offset": "Float64",
    "time": "Float64",
    "var": "String",
    "source": "String",
    "src": "String",
    "aux": "String",
    "type": "Enum(double, string, binary)",
    "double": "Float64",
    "text": "String",
    "raw": "Binary",
}
TYPES = ("double", "string", "binary")
#: Columns every batch has inside the reader (what entries() needs besides SCHEMA's).
_ALWAYS = frozenset(("line", "offset", "var", "source", "type", "double", "text", "nlines"))

_MAX_BANNER_LINES = 16
_BINARY_RECORD_END = 0x0A
_BINARY_OPEN = "<MOOS_BINARY>"
_BINARY_CLOSE = "</MOOS_BINARY>"
_MARKING = DATATYPE_MARKING.encode()

# The standard layout: no field wider than its column, so the value starts at character 53.
_STD_TIME = r"^-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)? +$"
_STD_KEY = r"^[^ ]+ +$"
_STD_SOURCE = r"^[^ ]* +$"
_TIME = r"^-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?$"
_DOUBLE = r"^(?:-?[0-9]+(?:\.[0-9]+)?|-?nan|-?inf)$"
_BINARY = r"^<MOOS_BINARY>File=.*,Offset=-?[0-9]+,Bytes=[0-9]+</MOOS_BINARY>$"


def _byte_per_char(err: UnicodeError) -> tuple[str, int]:
    # One U+FFFD per undecodable byte, as surrogateescape gives one surrogate per byte: the
    # two decodings have the same characters at the same places, so positions carry over.
    if not isinstance(err, UnicodeDecodeError):  # pragma: no cover - registered for decoding
        raise err
    return "\ufffd" * (err.end - err.start), err.end


codecs.register_error("fleetlog.byte-per-char", _byte_per_char)


def limit_threads(threads: int) -> bool:
    """Cap the columnar library's thread pool in this process (a recorder: 1).

    polars sizes its pool when it is first imported, so this works only before the first
    read; it returns False (and changes nothing) when polars is already loaded.
    """
    if "polars" in sys.modules:
        return False
    os.environ["POLARS_MAX_THREADS"] = str(max(1, threads))
    return True


def _polars() -> ModuleType:
    try:
        return importlib.import_module("polars")
    except ImportError as err:  # pragma: no cover - a dependency; a broken install only
        msg = "reading logs needs polars (pip install polars); it is not installed"
        raise StorageError(msg) from err


@dataclass(frozen=True)
class Batch:
    """One block's entries: what :meth:`AlogReader.frames` yields.

    Attributes:
        frame: the entries' columns (those asked for, of :data:`SCHEMA`).
        exact: the block was all UTF-8, so ``frame``'s strings are the file's bytes; when
            False, strings that held other bytes show U+FFFD and :meth:`entries` is exact.
    """

    frame: pl.DataFrame
    exact: bool
    _full: pl.DataFrame

    @property
    def height(self) -> int:
        """The number of entries."""
        return int(self.frame.height)

    def entries(self) -> Iterator[Entry]:
        """Yield the batch's rows as exact :class:`Entry` objects."""
        return _to_entries(self._full, self.exact)

    def layout(self) -> pl.DataFrame:
        """Return where each entry's key, source and value start in its first line.

        Columns ``kpos``, ``spos`` and ``vpos``: character positions in the entry's text
        (``raw`` decoded as UTF-8 with ``surrogateescape``), for tools that rewrite a column
        and keep the rest of the line's bytes (merge).
        """
        return self._full.select("kpos", "spos", "vpos")

    def head(self, rows: int) -> Batch:
        """Return the first ``rows`` entries."""
        return Batch(self.frame.head(rows), self.exact, self._full.head(rows))


@dataclass
class _Pass:
    """The state one pass carries from block to block."""

    lineno: int = 1  # the line number of the first line of the next block
    mark: bool = False  # DATATYPE MARKING seen
    entries: int = 0  # entries read so far (before ``where``)
    where: Callable[[pl.DataFrame], pl.Series] | None = None
    orphans: int = 0  # stray lines seen so far
    reported: int = 0  # stray lines already reported (raise) or counted (skip)


@dataclass
class _Parsed:
    """What parsing one block gave."""

    frame: pl.DataFrame  # the entries, with internal columns
    consumed: int  # lines of the block that are done (the rest is carried)
    mark: bool  # the DATATYPE MARKING state after the consumed lines
    orphans: list[int]  # line numbers of stray lines
    exact: bool  # the block was valid UTF-8
    scanned: int = 0  # entries read (before ``where``)


class AlogReader:
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
        return (batch.frame for batch in self.frames(columns, where))

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
        wanted = list(SCHEMA) if columns is None else list(columns)
        unknown = [name for name in wanted if name not in SCHEMA]
        if unknown:
            msg = f"unknown column(s) {', '.join(map(repr, unknown))}; known: {', '.join(SCHEMA)}"
            raise UsageError(msg)
        order = [name for name in SCHEMA if name in wanted]
        frames = self._frames(frozenset(order), where)
        return (Batch(frame.select(order), exact, frame) for frame, exact in frames)

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

    def _read(self, stream: LogBytes, size: int) -> tuple[bytes, bool]:
        """Read up to ``size`` bytes; return them and whether the stream was corrupt there."""
        try:
            return stream.read(size) or b"", False
        except StorageError:
            if self.errors == "raise":
                raise
            self.skipped += 1
            return b"", True
        except OSError as err:
            msg = f"cannot read {self.path}: {err.strerror or err}"
            raise StorageError(msg) from err
        except ValueError as err:  # I/O on the closed file
            if not stream.closed:
                raise
            msg = f"{self.path}: the reader was closed during a pass"
            raise StorageError(msg) from err

    def _pass(
        self,
        stream: LogBytes,
        head: bytes,
        want: frozenset[str],
        where: Callable[[pl.DataFrame], pl.Series] | None,
    ) -> Iterator[tuple[pl.DataFrame, bool]]:
        pl = _polars()
        state = _Pass(where=where)
        workers = min(_WORKERS, int(pl.thread_pool_size()))
        pool = ThreadPoolExecutor(workers, "fleetlog-read") if workers > 1 else None
        pending: deque[Future[_Parsed]] = deque()
        try:
            carry = head
            size = self.block_size
            while True:
                data, corrupt = self._read(stream, size)
                if not data:
                    while pending:
                        yield from self._account(pending.popleft().result(), state)
                    yield from self._finish(pl, state, carry, want, cut=corrupt or stream.truncated)
                    return
                buf = carry + data if carry else data
                end = buf.rfind(b"\n")
                if end < 0:
                    carry = buf
                    size *= 2  # one line longer than a block
                    continue
                cut = _entry_start(pl, buf, end) if pool is not None else None
                if cut is not None:
                    # The block ends where an entry starts, so it is whole: parse it while
                    # the next one is read (polars releases the GIL), in order.
                    block, carry = buf[: cut - 1], buf[cut:]
                    job = _Pass(lineno=state.lineno, mark=state.mark, where=where)
                    state.lineno += block.count(b"\n") + 1
                    state.mark = state.mark or (b"\n" + _MARKING + b"\n") in (b"\n" + block + b"\n")
                    assert pool is not None
                    pending.append(pool.submit(self._parse_job, pl, block, job, want))
                    while len(pending) > workers or (pending and pending[0].done()):
                        yield from self._account(pending.popleft().result(), state)
                    size = self.block_size
                    continue
                # No entry starts near the end of the block: find the unfinished entry by
                # parsing it, after the blocks before it.
                while pending:
                    yield from self._account(pending.popleft().result(), state)
                parsed = self._parse(pl, buf[:end], state, want, final=False)
                kept = buf.count(b"\n", 0, end) + 1 - parsed.consumed
                carry = buf[_line_start(buf, end, kept) :]
                yield from self._account(parsed, state)
                state.lineno += parsed.consumed
                state.mark = parsed.mark
                size = self.block_size if parsed.consumed else size * 2
        finally:
            for future in pending:
                future.cancel()
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
            stream.close()
            self._open.discard(stream)

    def _parse_job(self, pl: ModuleType, block: bytes, job: _Pass, want: frozenset[str]) -> _Parsed:
        return self._parse(pl, block, job, want, final=False, at_head=True)

    def _finish(
        self, pl: ModuleType, state: _Pass, carry: bytes, want: frozenset[str], *, cut: bool
    ) -> Iterator[tuple[pl.DataFrame, bool]]:
        """Parse the last block: apply the cut-tail rules (MOOS_FORMAT.md §12)."""
        end = carry.rfind(b"\n")
        tail = carry[end + 1 :]
        complete = True
        mark_at_end = False
        if tail:
            # A cut line that starts a new entry (or a comment) proves the entry before it
            # was whole; a cut continuation line leaves that entry's value unknown.
            self.truncated = True
            complete = tail.startswith(b"%") or _starts_entry(tail)
            mark_at_end = tail == _MARKING
        elif cut:
            self.truncated = True
            complete = False
        if end >= 0:
            parsed = self._parse(
                pl,
                carry[:end],
                state,
                want,
                final=True,
                complete=complete,
                mark_at_end=mark_at_end,
            )
            yield from self._account(parsed, state)
        if state.orphans > state.reported:
            if self.errors == "raise":
                raise _stray_error(self.path, state.orphans - state.reported, None)
            self.skipped += state.orphans - state.reported
            state.reported = state.orphans

    def _account(self, parsed: _Parsed, state: _Pass) -> Iterator[tuple[pl.DataFrame, bool]]:
        """Yield a block's entries, counting or raising on its stray lines.

        The line parser raised at the first entry after a stray line, having yielded the
        entries before it; under ``"skip"`` it counted them.
        """
        frame = parsed.frame
        state.orphans += len(parsed.orphans)
        if self.errors == "skip":
            self.skipped += state.orphans - state.reported
            state.reported = state.orphans
        elif state.orphans > state.reported:
            pending = state.orphans - state.reported - len(parsed.orphans)
            first = parsed.orphans[0] if not pending else 0
            later = frame["line"].filter(frame["line"] > first)
            if later.len():
                line = int(later[0])
                count = pending + sum(1 for n in parsed.orphans if n < line)
                before = frame.filter(frame["line"] < line)
                if before.height:
                    yield before, parsed.exact
                raise _stray_error(self.path, count, line)
        state.entries += parsed.scanned
        self.scanned = state.entries
        if frame.height:
            yield frame, parsed.exact

    def _parse(
        self,
        pl: ModuleType,
        block: bytes,
        state: _Pass,
        want: frozenset[str],
        *,
        final: bool,
        complete: bool = True,
        mark_at_end: bool = False,
        at_head: bool = False,
    ) -> _Parsed:
        """Parse the whole lines of ``block`` (no trailing newline) into entries."""
        exact = True
        try:
            text = block.decode("utf-8")
        except UnicodeDecodeError:
            text = block.decode("utf-8", "fleetlog.byte-per-char")
            exact = False
        return _parse_block(
            pl,
            text,
            block if not exact else None,
            state,
            self.logstart,
            want,
            final=final,
            complete=complete,
            mark_at_end=mark_at_end,
            on_drop=self._dropped,
            at_head=at_head,
        )

    def _dropped(self) -> None:
        self.truncated = True

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
        return self._entries(self._frames(_ALWAYS, where))

    def _entries(self, frames: Iterator[tuple[pl.DataFrame, bool]]) -> Iterator[Entry]:
        try:
            for frame, exact in frames:
                yield from _to_entries(frame, exact)
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
        name = self.path.name
        if compression_of(self.path):
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
                # Never ask read() for more than the file holds: it allocates what it is asked
                # for, and a forged Bytes=10**12 would be a MemoryError, not an error message.
                end = os.fstat(file.fileno()).st_size
                file.seek(ref.offset)
                data = file.read(max(0, min(ref.size + 1, end - ref.offset)))
        except (OSError, OverflowError) as err:
            why = err.strerror if isinstance(err, OSError) and err.strerror else err
            msg = f"{where}: cannot read {blog} at Offset={ref.offset}: {why}"
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


def _stray_error(path: Path, count: int, line: int | None) -> FormatError:
    where = f"before line {line}" if line is not None else "after the banner"
    msg = f"{count} line(s) {where} are neither entries nor comments"
    return FormatError(msg, str(path), line)


def _starts_entry(line: bytes) -> bool:
    # ASCII digits only: a time column never starts otherwise.
    if not line:
        return False
    c = line[0]
    if 0x30 <= c <= 0x39:
        return True
    return c == 0x2D and len(line) > 1 and 0x30 <= line[1] <= 0x39


def _entry_start(pl: ModuleType, buf: bytes, end: int) -> int | None:
    """Return where the last entry line of ``buf[:end]`` starts (not at 0), or None.

    Looks at the last :data:`_CUT_LOOKBACK` whole lines only, with the reader's own rule
    for an entry line (so a block cut there ends with whole entries).
    """
    starts: list[int] = []
    pos = end
    while len(starts) < _CUT_LOOKBACK and pos > 0:
        start = buf.rfind(b"\n", 0, pos) + 1
        if start == 0:
            break
        starts.append(start)
        pos = start - 1
    if not starts:
        return None
    ends = [end, *(start - 1 for start in starts[:-1])]
    texts = [
        buf[a:b].decode("utf-8", "fleetlog.byte-per-char")
        for a, b in zip(starts, ends, strict=True)
    ]
    lines = pl.DataFrame({"l": texts}).with_row_index("idx")
    entries = lines.filter(_std_mask(pl))["idx"].to_list()
    others = lines.filter(~_std_mask(pl) & pl.col("l").str.contains(r"^-?[0-9]"))
    if others.height:
        entries += _general(pl, others)["idx"].to_list()
    return starts[min(entries)] if entries else None


def _line_start(buf: bytes, end: int, lines: int) -> int:
    """Return where the last ``lines`` lines of ``buf[:end]`` start (``end`` if none)."""
    if lines <= 0:
        return end + 1
    pos = end
    for _ in range(lines):
        pos = buf.rfind(b"\n", 0, pos)
        if pos < 0:
            return 0
    return pos + 1


# --------------------------------------------------------------------------------------------
# The block parser


def _all_spaces(pl: ModuleType, expr: Any, width: Any) -> Any:
    """An expression: ``expr`` holds at least ``width`` characters, the first ``width`` spaces."""
    return (expr.str.len_chars() >= width) & (
        expr.str.slice(0, width).str.strip_chars_start(" ").str.len_bytes() == 0
    )


def _std_mask(pl: ModuleType) -> Any:
    """An expression: the line ``l`` is an entry with no field wider than its column."""
    line = pl.col("l")
    source_field = line.str.slice(37, 16)
    return (
        source_field.str.len_chars().eq(16)
        & line.str.slice(0, 16).str.contains(_STD_TIME)
        & line.str.slice(16, 21).str.contains(_STD_KEY)
        & source_field.str.contains(_STD_SOURCE)
    )


def _general(pl: ModuleType, lines: pl.DataFrame) -> pl.DataFrame:
    """Split lines whose columns overflow (or are not entries) by the writer's column rule.

    Follows the columns: each field is left-justified to its width (15, 20, 15) or wider,
    then one separator space. Returns the lines that are entries, with their fields and
    the character positions of the key, source and value.
    """
    col = pl.col
    zero = pl.lit(0)
    frame = (
        lines.lazy()
        .with_columns(col("l").str.splitn(" ", 2).struct.rename_fields(["t", "r1"]).alias("p"))
        .unnest("p")
        .with_columns(lt=col("t").str.len_chars().cast(pl.Int64))
        .with_columns(pad1=pl.max_horizontal(15 - col("lt"), zero))
        .filter(
            col("r1").is_not_null()
            & col("t").str.contains(_TIME)
            & _all_spaces(pl, col("r1"), col("pad1"))
        )
        .with_columns(r1k=col("r1").str.slice(col("pad1")))
        .filter((col("r1k").str.len_bytes() > 0) & ~col("r1k").str.starts_with(" "))
        .with_columns(col("r1k").str.splitn(" ", 2).struct.rename_fields(["k", "r2"]).alias("p"))
        .unnest("p")
        .with_columns(lk=col("k").str.len_chars().cast(pl.Int64))
        .with_columns(pad2=pl.max_horizontal(20 - col("lk"), zero))
        .filter(col("r2").is_not_null() & _all_spaces(pl, col("r2"), col("pad2")))
        .with_columns(r3=col("r2").str.slice(col("pad2")))
        .with_columns(col("r3").str.splitn(" ", 2).struct.rename_fields(["s", "r4"]).alias("p"))
        .unnest("p")
        .with_columns(ls=col("s").str.len_chars().cast(pl.Int64))
        .with_columns(pad3=pl.max_horizontal(15 - col("ls"), zero))
        .filter(col("r4").is_not_null() & _all_spaces(pl, col("r4"), col("pad3")))
        .with_columns(
            kpos=pl.max_horizontal(col("lt"), pl.lit(15)) + 1,
        )
        .with_columns(spos=col("kpos") + pl.max_horizontal(col("lk"), pl.lit(20)) + 1)
        .with_columns(vpos=col("spos") + pl.max_horizontal(col("ls"), pl.lit(15)) + 1)
        .select(
            "idx",
            "l",
            offset=col("t").cast(pl.Float64, strict=False),
            var="k",
            source="s",
            v=col("r4").str.slice(col("pad3")),
            kpos=col("kpos").cast(pl.Int32),
            spos=col("spos").cast(pl.Int32),
            vpos=col("vpos").cast(pl.Int32),
        )
    )
    return frame.collect()


def _parse_block(
    pl: ModuleType,
    text: str,
    block: bytes | None,
    state: _Pass,
    logstart: float | None,
    want: frozenset[str],
    *,
    final: bool,
    complete: bool,
    mark_at_end: bool,
    on_drop: Any,
    at_head: bool = False,
) -> _Parsed:
    """Parse the lines of ``text``; ``block`` is its bytes when they were not all UTF-8.

    ``final``: the file ends here (the cut-tail rules apply to the last entry). ``at_head``:
    the next line, not in ``text``, starts an entry, so every entry here is finished.
    Otherwise the last entry may go on in the next block: it is left out (``consumed``).
    """
    col = pl.col
    line = col("l")
    lines = pl.DataFrame({"l": [text]}).select(line.str.split("\n").explode()).with_row_index("idx")
    n = lines.height
    # Every line as if it had the standard layout, and whether it has: one pass, the
    # expressions evaluated in parallel.
    source_field = line.str.slice(37, 16)
    parsed = (
        lines.lazy()
        .select(
            "idx",
            "l",
            std=_std_mask(pl),
            offset=line.str.slice(0, 16).str.strip_chars_end(" ").cast(pl.Float64, strict=False),
            var=line.str.slice(16, 21).str.strip_chars_end(" "),
            source=source_field.str.strip_chars_end(" "),
            v=line.str.slice(53),
        )
        .collect()
    )
    std_mask = parsed["std"]
    parsed = parsed.with_columns(
        kpos=pl.lit(16, pl.Int32), spos=pl.lit(37, pl.Int32), vpos=pl.lit(53, pl.Int32)
    )
    rest = lines.filter(~std_mask)
    general_idx = None
    entry_mask = std_mask
    if rest.height:
        candidates = rest.filter(line.str.contains(r"^-?[0-9]"))
        if candidates.height:
            general = _general(pl, candidates)
            if general.height:
                # the overflowing lines' fields replace the standard layout's, in place
                general_idx = general["idx"]
                parsed = parsed.with_columns(
                    parsed[name].scatter(general_idx, general[name])
                    for name in ("offset", "var", "source", "v", "kpos", "spos", "vpos")
                )
                entry_mask = std_mask.clone().scatter(general_idx, True)
        comments = rest.filter(line.str.starts_with("%"))
    else:
        comments = rest
    heads = parsed.filter(entry_mask).drop("std")
    comment_idx = comments["idx"]
    n_heads = heads.height + comments.height

    # Continuation lines join the entry before them; before any entry, or after a comment,
    # they are stray lines.
    orphans: list[int] = []
    cont = pl.lit(None, pl.String)
    if n_heads < n:
        is_head = std_mask.clone()
        is_head = is_head.scatter(comment_idx, True) if comments.height else is_head
        is_head = is_head.scatter(general_idx, True) if general_idx is not None else is_head
        is_entry = entry_mask
        tagged = lines.with_columns(
            gid=is_head.cast(pl.Int32).cum_sum(), head=is_head, entry=is_entry
        )
        owner = tagged.filter(col("head")).select("gid", "entry")
        conts = tagged.filter(~col("head")).drop("entry").join(owner, on="gid", how="left")
        conts = conts.with_columns(col("entry").fill_null(False))
        stray = conts.filter(~col("entry"))
        orphans = [int(i) + state.lineno for i in stray["idx"]]
        attached = conts.filter(col("entry"))
        if attached.height:
            joined = attached.group_by("gid", maintain_order=True).agg(
                col("l").str.join("\n").alias("c")
            )
            # the entry that owns group g is the head line at the g-th head
            head_idx = tagged.filter(col("head"))["idx"]
            joined = joined.with_columns(idx=head_idx.gather(joined["gid"] - 1)).drop("gid")
            heads = heads.join(joined, on="idx", how="left", maintain_order="left")
            cont = col("c")
    if "c" not in heads.columns:
        heads = heads.with_columns(c=cont)

    # The DATATYPE MARKING state where each entry was finished (at the next head, or at the
    # end of the file): the line parser classified an entry then.
    end_mark = state.mark
    mark_lines = comments.filter(line == DATATYPE_MARKING)["idx"] if comments.height else None
    mark: Any = state.mark
    if not state.mark and mark_lines is not None and mark_lines.len():
        end_mark = True
        first = int(mark_lines[0])
        # entries after the marking line, and the one it finished (no comment in between)
        before = heads["idx"].filter(heads["idx"] < first)
        finisher = -1
        if before.len():
            last = int(before[-1])
            if not comment_idx.filter((comment_idx > last) & (comment_idx < first)).len():
                finisher = last
        mark = (col("idx") > first) | (col("idx") == finisher)

    # What is done: in a non-final block, the last entry may go on in the next block.
    consumed = n
    last_head = max(
        int(heads["idx"][-1]) if heads.height else -1,
        int(comment_idx[-1]) if comments.height else -1,
    )
    last_is_entry = heads.height > 0 and int(heads["idx"][-1]) == last_head
    dropped = False
    if last_is_entry and not final and not at_head:
        consumed = last_head
        heads = heads.slice(0, heads.height - 1)
    elif last_is_entry and final:
        # the last entry: whole only if the file was, and if it ends with its terminator
        value = heads["v"][-1]
        more = heads["c"][-1]
        last_part = more.rsplit("\n", 1)[-1] if more is not None else value
        terminated = last_part.endswith(" ") or (
            value.startswith(_BINARY_OPEN) and last_part.endswith(_BINARY_CLOSE)
        )
        if not complete or not terminated:
            heads = heads.slice(0, heads.height - 1)
            dropped = True
        elif mark_at_end and not end_mark:
            mark = pl.when(col("idx") == last_head).then(True).otherwise(pl.lit(mark))
    if dropped:
        on_drop()
    scanned = heads.height
    if state.where is not None and heads.height:
        keep = state.where(
            heads.select(
                line=(col("idx") + state.lineno).cast(pl.Int64),
                offset="offset",
                var="var",
                source="source",
            )
        )
        heads = heads.filter(keep)
    frame = _typed(pl, heads, mark, state.lineno, logstart, want, cont is not None)
    if block is not None:
        frame = _exact_raw(pl, frame, block, state.lineno)
    return _Parsed(frame, consumed, end_mark, orphans, block is None, scanned)


def _typed(
    pl: ModuleType,
    heads: pl.DataFrame,
    mark: Any,
    first_line: int,
    logstart: float | None,
    want: frozenset[str],
    continued: bool = True,
) -> pl.DataFrame:
    """Turn entry heads (fields of the first line, continuation text) into typed columns.

    ``mark`` is a bool when the whole block has one DATATYPE MARKING state (nearly always:
    the expressions are then simpler), else an expression; ``continued`` says whether any
    entry has continuation lines.
    """
    col = pl.col
    text0 = col("text0")
    value = (
        pl.when(col("c").is_not_null()).then(col("v") + "\n" + col("c")).otherwise(col("v"))
        if continued
        else col("v")
    )
    frame = heads.lazy().with_columns(value=value)
    frame = frame.with_columns(
        term=col("value").str.ends_with(" "), text0=col("value").str.strip_suffix(" ")
    )
    if mark is False:
        frame = frame.with_columns(
            binary=~col("term") & text0.str.contains(_BINARY),
            dmark=pl.lit(False),
            smark=pl.lit(False),
            body=text0.str.strip_chars_end(" "),
        ).with_columns(
            double=~col("binary")
            & col("body").str.contains(_DOUBLE)
            & (
                text0.str.len_bytes()
                == pl.max_horizontal(pl.lit(12, pl.UInt32), col("body").str.len_bytes())
            )
        )
    else:
        frame = frame.with_columns(
            mk=pl.lit(True) if mark is True else mark,
        ).with_columns(
            binary=~col("term") & text0.str.contains(_BINARY),
            dmark=col("mk") & text0.str.starts_with("D:"),
            smark=col("mk") & text0.str.starts_with("S:"),
            body=text0.str.strip_chars_end(" "),
        )
        body = (
            pl.when(col("dmark"))
            .then(text0.str.slice(2).str.strip_chars_end(" "))
            .otherwise("body")
        )
        frame = frame.with_columns(body=body).with_columns(
            double=~col("binary")
            & col("body").str.contains(_DOUBLE)
            & pl.when(col("mk"))
            .then(col("dmark"))
            .otherwise(
                text0.str.len_bytes()
                == pl.max_horizontal(pl.lit(12, pl.UInt32), col("body").str.len_bytes())
            )
        )
    exprs: dict[str, Any] = {
        "line": (col("idx") + first_line).cast(pl.Int64),
        "offset": col("offset"),
        "time": col("offset") + logstart if logstart is not None else pl.lit(None, pl.Float64),
        "var": col("var"),
        "source": col("source"),
        "type": pl.when(col("binary"))
        .then(pl.lit("binary"))
        .when(col("double"))
        .then(pl.lit("double"))
        .otherwise(pl.lit("string"))
        .cast(pl.Enum(TYPES)),
        "double": pl.when(col("double")).then(col("body").cast(pl.Float64, strict=False)),
        "text": pl.when(col("double"))
        .then(col("body"))
        .when(col("smark") & ~col("binary"))
        .then(text0.str.slice(2))
        .otherwise(text0),
        "raw": pl.when(col("c").is_not_null())
        .then(col("l") + "\n" + col("c"))
        .otherwise(col("l"))
        .cast(pl.Binary),
        "nlines": pl.when(col("c").is_not_null())
        .then(col("c").str.count_matches("\n") + 2)
        .otherwise(1),
    }
    names = [name for name in exprs if name in want or name in _ALWAYS]
    extra = [name for name in ("kpos", "spos", "vpos") if name in heads.columns]
    result = frame.select(*(exprs[name].alias(name) for name in names), *extra).collect()
    if "src" in want or "aux" in want:
        result = _with_source_parts(pl, result)
    return result


def _with_source_parts(pl: ModuleType, frame: pl.DataFrame) -> pl.DataFrame:
    """Add ``src`` and ``aux``, computed once per distinct source."""
    if not frame.height:
        return frame.with_columns(src=pl.col("source"), aux=pl.col("source"))
    sources = frame["source"].unique().to_list()
    parts = [split_source(s) for s in sources]
    src = pl.Series([p[0] for p in parts], dtype=pl.String)
    aux = pl.Series([p[1] for p in parts], dtype=pl.String)
    old = pl.Series(sources, dtype=pl.String)
    return frame.with_columns(
        src=pl.col("source").replace_strict(old, src, return_dtype=pl.String),
        aux=pl.col("source").replace_strict(old, aux, return_dtype=pl.String),
    )


def _exact_raw(pl: ModuleType, frame: pl.DataFrame, block: bytes, first_line: int) -> pl.DataFrame:
    """Fill ``raw`` with the exact bytes of each entry (a block that is not all UTF-8)."""
    lines = block.split(b"\n")
    raw = []
    for line, count in zip(frame["line"].to_list(), frame["nlines"].to_list(), strict=True):
        start = line - first_line
        raw.append(b"\n".join(lines[start : start + count]))
    return frame.with_columns(raw=pl.Series(raw, dtype=pl.Binary))


def _to_entries(frame: pl.DataFrame, exact: bool) -> Iterator[Entry]:
    """Yield a batch's rows as :class:`Entry` objects (exact values from ``raw`` if needed).

    In slices of :data:`_ENTRY_CHUNK` rows: the Python objects held at once, and the time
    the GIL is held for one conversion, stay small whatever the block size (a player at 1x
    must not wait for a whole block's conversion).
    """
    for start in range(0, frame.height, _ENTRY_CHUNK):
        yield from _chunk_entries(frame.slice(start, _ENTRY_CHUNK), exact)


def _chunk_entries(frame: pl.DataFrame, exact: bool) -> Iterator[Entry]:

    columns = [
        frame[name].to_list()
        for name in ("offset", "var", "source", "type", "double", "text", "line")
    ]
    if exact:
        for offset, key, source, kind, double, text, line in zip(*columns, strict=True):
            if kind == "double":
                value: float | str | BinaryRef = double
            elif kind == "string":
                value = text
            else:
                value = parse_binary_ref(text) or text
            yield Entry(offset, key, source, value, text, line)
        return
    raws = frame["raw"].to_list()
    positions = [frame[name].to_list() for name in ("kpos", "spos", "vpos")]
    for (offset, key, source, kind, double, text, line), raw, kpos, spos, vpos in zip(
        zip(*columns, strict=True), raws, *positions, strict=True
    ):
        if "\ufffd" in key + source + text:
            whole = raw.decode("utf-8", "surrogateescape")
            key = whole[kpos : kpos + len(key)]
            source = whole[spos : spos + len(source)]
            if kind != "double":
                value_text = whole[vpos:]
                value_text = (
                    value_text.removesuffix(" ") if value_text.endswith(" ") else value_text
                )
                text = value_text[len(value_text) - len(text) :]
        if kind == "double":
            value = double
        elif kind == "string":
            value = text
        else:
            value = parse_binary_ref(text) or text
        yield Entry(offset, key, source, value, text, line)


# --------------------------------------------------------------------------------------------
# The end of a log


def read_tail(path: str | os.PathLike[str], size: int) -> pl.DataFrame:
    """Return the entries among the last ``size`` bytes of a plain alog, in file order.

    What a listing or a player needs from the end of a log (its last times) without reading
    the whole file. The first line there is skipped (it may be cut), as are stray lines
    (the tail may start inside a multi-line value), and an entry whose line is still being
    written is not read. ``line`` counts from the first line read, not from the file's start.

    Raises:
        StorageError: the file cannot be read.
    """
    file_path = Path(path)
    try:
        with file_path.open("rb") as file:
            end = file.seek(0, os.SEEK_END)
            start = max(0, end - size)
            file.seek(start)
            data = file.read(end - start)
    except OSError as err:
        msg = f"cannot read {file_path}: {err.strerror or err}"
        raise StorageError(msg) from err
    if start > 0:
        data = data[data.find(b"\n") + 1 :] if b"\n" in data else b""
    pl = _polars()
    cut = data.rfind(b"\n")
    tail = data[cut + 1 :]
    want = frozenset(("line", "offset", "var", "source", "type", "double", "text"))
    columns = [name for name in SCHEMA if name in want]
    if cut < 0:
        return _typed(pl, _no_heads(pl), pl.lit(False), 1, None, want).select(columns)
    try:
        text = data[:cut].decode("utf-8")
        block = None
    except UnicodeDecodeError:
        text = data[:cut].decode("utf-8", "fleetlog.byte-per-char")
        block = data[:cut]
    parsed = _parse_block(
        pl,
        text,
        block,
        _Pass(),
        None,
        want,
        final=True,
        complete=not tail or tail.startswith(b"%") or _starts_entry(tail),
        mark_at_end=False,
        on_drop=lambda: None,
    )
    return parsed.frame.select(columns)


def parse_lines(data: bytes, *, final: bool = False) -> tuple[pl.DataFrame, int]:
    """Parse log text that starts at a line's start; return entries and the bytes they take.

    For scans that resume where they stopped (a growing file): without ``final``, the
    last entry and any cut line are left for the next call (its value may go on), and the
    byte count says where that call starts; with ``final``, the last whole entry is read
    too. Stray lines are ignored. Columns: ``line`` (from 1 at ``data``'s start),
    ``offset``, ``var``, ``source``, ``type``, ``double``, ``text``.
    """
    pl = _polars()
    want = frozenset(("line", "offset", "var", "source", "type", "double", "text"))
    columns = [name for name in SCHEMA if name in want]
    end = data.rfind(b"\n")
    if end < 0:
        return _typed(pl, _no_heads(pl), pl.lit(False), 1, None, want).select(columns), 0
    block = data[:end]
    try:
        text = block.decode("utf-8")
        raw = None
    except UnicodeDecodeError:
        text = block.decode("utf-8", "fleetlog.byte-per-char")
        raw = block
    tail = data[end + 1 :]
    parsed = _parse_block(
        pl,
        text,
        raw,
        _Pass(),
        None,
        want,
        final=final,
        complete=not tail or tail.startswith(b"%") or _starts_entry(tail),
        mark_at_end=False,
        on_drop=lambda: None,
    )
    kept = block.count(b"\n") + 1 - parsed.consumed
    used = len(data) if final else _line_start(data, end, kept)
    return parsed.frame.select(columns), min(used, len(data))


def _no_heads(lib: ModuleType) -> pl.DataFrame:
    empty: pl.DataFrame = lib.DataFrame(
        schema={
            "idx": lib.UInt32,
            "l": lib.String,
            "offset": lib.Float64,
            "var": lib.String,
            "source": lib.String,
            "v": lib.String,
            "c": lib.String,
        }
    )
    return empty


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
