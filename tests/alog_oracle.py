r"""The line parser that fleetlog's first reader was: the oracle of the columnar reader.

fleetlog reads every log through one path, :mod:`fleetlog.storage.columnar`. This module
keeps the earlier line-at-a-time parser (``EntryParser``/``iter_entries`` from
``fleetlog.moos.alog`` and ``AlogReader`` from ``fleetlog.storage.readers``, as they were)
for the tests alone: property tests compare the two readers on generated, fuzzed and
recorded logs, and the rules of MOOS_FORMAT.md §12 are written here in their plainest form.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.moos.alog import (
    BANNER_RULE,
    DATATYPE_MARKING,
    Banner,
    BinaryRef,
    Entry,
    parse_banner,
    parse_binary_ref,
)
from fleetlog.storage.columnar import Errors
from fleetlog.storage.decompress import LogText, compression_of, log_kind, open_text
from fleetlog.storage.ordering import Record

if TYPE_CHECKING:
    from typing import Self

__all__ = ["AlogReader", "EntryParser", "classify_value", "iter_entries"]

_DOUBLE_RE = re.compile(r"-?[0-9]+(?:\.[0-9]+)?|-?nan|-?inf")
_TIME_RE = re.compile(r"-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?")
_BINARY_OPEN = "<MOOS_BINARY>"
_BINARY_CLOSE = "</MOOS_BINARY>"
_MAX_BANNER_LINES = 16
_BINARY_RECORD_END = 0x0A


def classify_value(
    text: str, *, mark_data_type: bool = False, binary: bool = True
) -> tuple[float | str | BinaryRef, str]:
    """Decide a value's type from its text as written; return ``(value, clean_text)``.

    With MarkDataType the ``D:``/``S:`` marker decides. Without it, a value that is exactly a
    double as pLogger pads it (``%.Nf`` left-justified to 12, or wider with no padding) is a
    double and anything else a string: ``"0.5"`` unpadded is a string, because pLogger would
    have written the double 0.5 as ``"0.5"`` plus 9 spaces. A ``<MOOS_BINARY>`` tag is binary
    either way, unless ``binary`` is False.

    Args:
        text: the value part of an entry without its terminator space.
        mark_data_type: the file was written with MarkDataType (a ``D:``/``S:`` marker).
        binary: whether the text may be a binary reference. Pass False when the value came
            with a terminator space: pLogger writes binary references without one, so such a
            value is a string that merely looks like a reference.
    """
    if binary and text.startswith(_BINARY_OPEN):
        ref = parse_binary_ref(text)
        if ref is not None:
            return ref, text
    if mark_data_type:
        if text.startswith("D:"):
            body = text[2:].rstrip(" ")
            if _DOUBLE_RE.fullmatch(body):
                return float(body), body
        elif text.startswith("S:"):
            return text[2:], text[2:]
        return text, text
    body = text.rstrip(" ")
    if body and len(text) == max(12, len(body)) and _DOUBLE_RE.fullmatch(body):
        return float(body), body
    return text, text


def _entry_fields(line: str) -> tuple[str, str, str, str] | None:
    """Split an entry's first line into time, key, source and raw value (with terminator).

    Follows the writer's columns: each field is left-justified to its width (15, 20, 15) or
    wider, then one separator space. Returns None when the line is not shaped like an entry.
    """
    sp = line.find(" ")
    if sp <= 0:
        return None
    time_text = line[:sp]
    if not _TIME_RE.fullmatch(time_text):
        return None
    pos = max(15, sp) + 1
    if line[sp:pos].strip(" "):
        return None
    key_end = line.find(" ", pos)
    if key_end <= pos:
        return None
    key = line[pos:key_end]
    pos = max(pos + 20, key_end) + 1
    if line[key_end:pos].strip(" "):
        return None
    src_end = line.find(" ", pos)
    if src_end < 0:
        return None
    source = line[pos:src_end]
    vpos = max(pos + 15, src_end) + 1
    if line[src_end:vpos].strip(" ") or len(line) < vpos:
        return None
    return time_text, key, source, line[vpos:]


def _is_ascii_digit(c: str) -> bool:
    return "0" <= c <= "9"


def _starts_entry(line: str) -> bool:
    # ASCII digits only: str.isdigit() also accepts "²" or "٣", which never start pLogger's
    # time column but may start a continuation line.
    if not line:
        return False
    c = line[0]
    return _is_ascii_digit(c) or (c == "-" and len(line) > 1 and _is_ascii_digit(line[1]))


class EntryParser:
    r"""Incremental alog entry parser: feed lines, get entries; keeps multi-line values whole.

    Lines are given without their ``\n``. Banner and comment lines (``%``) are skipped. The
    parser is strict only where a real file cannot differ: a line that starts like an entry
    but is not shaped like one continues the previous value, as a continuation line would.

    Attributes:
        mark_data_type: read ``D:``/``S:`` markers (set from the banner by :func:`iter_entries`).
        orphans: continuation lines seen before any entry (a file cut at its head).
        dropped: last entries dropped by :meth:`close` because they were cut short.
    """

    def __init__(self, *, mark_data_type: bool = False) -> None:
        self.mark_data_type = mark_data_type
        self.orphans = 0
        self.dropped = 0
        self._head: tuple[float, str, str, int] | None = None
        self._parts: list[str] = []

    def feed(self, line: str, lineno: int = 0) -> Entry | None:
        """Take the next line; return the entry it completes, if any."""
        if line.startswith("%"):
            return self._finish()
        if _starts_entry(line):
            fields = _entry_fields(line)
            if fields is not None:
                done = self._finish()
                time_text, key, source, raw = fields
                self._head = (float(time_text), key, source, lineno)
                self._parts = [raw]
                return done
        if self._head is None:
            self.orphans += 1
            return None
        self._parts.append(line)
        return None

    def close(self, *, complete: bool = True) -> Entry | None:
        r"""Finish the last entry.

        pLogger ends every entry with its terminator (a space, or the binary tag's close), so
        a last entry without one was cut inside a multi-line value (``"hello"`` of
        ``"hello\ndebug"``): it is dropped like a cut line, and counted in :attr:`dropped`.

        Args:
            complete: False when the last line had no ``\n`` (a truncated file); its entry is
                then dropped, because its value may be cut short.
        """
        if self._head is None:
            return None
        if not complete or not self._terminated():
            self._head = None
            self._parts = []
            self.dropped += 1
            return None
        return self._finish()

    def _terminated(self) -> bool:
        last = self._parts[-1]
        return last.endswith(" ") or (
            self._parts[0].startswith(_BINARY_OPEN) and last.endswith(_BINARY_CLOSE)
        )

    def _finish(self) -> Entry | None:
        head = self._head
        if head is None:
            return None
        self._head = None
        raw = "\n".join(self._parts)
        self._parts = []
        if raw.endswith(" "):
            # The terminator space: a string or a double, never a binary reference.
            text = raw[:-1]
            terminated = True
        else:
            # A binary reference, or (not what pLogger writes) a value without its
            # terminator space, kept as it stands.
            text = raw
            terminated = False
        value, clean = classify_value(
            text, mark_data_type=self.mark_data_type, binary=not terminated
        )
        offset, key, source, lineno = head
        return Entry(offset, key, source, value, clean, lineno)


def iter_entries(
    lines: Iterable[str], *, mark_data_type: bool = False, parser: EntryParser | None = None
) -> Iterator[Entry]:
    r"""Yield the entries of alog text given as ``\n``-terminated lines.

    A last line without ``\n`` is treated as truncated: its entry is dropped. The banner's
    ``DATATYPE MARKING ON`` line switches marker reading on.

    A reader that knows its text was cut exactly after a ``\n`` (a compressed stream that
    ended early) passes an empty last line: the entry before it may be missing continuation
    lines, so it is dropped too. Without that mark a cut at a line boundary inside a
    multi-line value is indistinguishable from a whole file.

    Args:
        lines: the text's lines, each ending in ``\n`` except perhaps the last.
        mark_data_type: read ``D:``/``S:`` markers from the start.
        parser: the parser to use, for callers that want its ``orphans`` and ``dropped``
            counts afterwards; a new one by default.
    """
    if parser is None:
        parser = EntryParser(mark_data_type=mark_data_type)
    elif mark_data_type:
        parser.mark_data_type = True
    complete = True
    for lineno, line in enumerate(lines, start=1):
        if line.endswith("\n"):
            body = line[:-1]
        else:
            complete = False
            body = line
        if body == DATATYPE_MARKING:
            parser.mark_data_type = True
        if not complete:
            # A cut line that starts a new entry (or a comment) proves the entry before it
            # was whole; a cut continuation line leaves that entry's value unknown.
            complete = body.startswith("%") or _starts_entry(body)
            break
        entry = parser.feed(body, lineno)
        if entry is not None:
            yield entry
    last = parser.close(complete=complete)
    if last is not None:
        yield last


# --------------------------------------------------------------------------------------------
# The alog reader


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
        xlog = log_kind(self.path) == ".xlog"
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
