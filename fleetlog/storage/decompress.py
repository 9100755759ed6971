r"""Log files opened for reading: plain, gzip and zstd, streamed, tolerating a cut tail.

This is the byte layer under every reader (:mod:`fleetlog.storage.columnar`, the catalog's
scans): :func:`open_bytes` and :func:`open_text` stream a ``.alog``, ``.alog.gz``, ``.alog.zst``
(or any other log file) decompressing as they go and stopping quietly where a crashed
recorder's stream was cut; the stream's ``truncated`` says so afterwards.

Text is decoded as UTF-8 with ``errors="surrogateescape"``, so any byte a value held survives
(``str.encode("utf-8", "surrogateescape")`` gives it back), and lines are split at ``\n``
only, so a ``\r`` inside a value stays in it.
"""

from __future__ import annotations

import io
import os
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import zstandard

from fleetlog.errors import StorageError

if TYPE_CHECKING:
    from _typeshed import WriteableBuffer

__all__ = ["LogBytes", "LogText", "compression_of", "log_kind", "open_bytes", "open_text"]

#: Compressed bytes read from the file at a time.
_READ_SIZE = 16 * 1024
#: zstd input fed at a time: zstandard's decompressobj has no output limit, so a small input
#: step keeps one decompressed piece small (a zstd block, at most 128 KiB, or the step times
#: the compression ratio).
_ZSTD_STEP = 8 * 1024
#: Largest piece of decompressed gzip output held at once.
_MAX_PIECE = 32 * 1024
_GZIP_WBITS = 16 + zlib.MAX_WBITS


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


def compression_of(path: Path) -> str:
    """Return ``"gzip"`` for a ``.gz`` file, ``"zstd"`` for a ``.zst`` one, else ``""``."""
    suffix = path.suffix.lower()
    if suffix == ".gz":
        return "gzip"
    if suffix == ".zst":
        return "zstd"
    return ""


def log_kind(path: Path) -> str:
    """Return ``".alog"``, ``".xlog"`` or another suffix, ignoring a compression suffix."""
    name = path.name
    if compression_of(path):
        name = name[: -len(path.suffix)]
    return Path(name).suffix.lower()


class LogBytes(io.BufferedReader):
    """A log file opened for reading as (decompressed) bytes; what :func:`open_bytes` returns.

    Attributes:
        path: the file.
        compression: ``""``, ``"gzip"`` or ``"zstd"``.
    """

    def __init__(self, raw: io.RawIOBase, path: Path, state: _StreamState) -> None:
        super().__init__(raw, buffer_size=1 << 16)
        self.path = path
        self.compression = state.compression
        self._state = state

    @property
    def truncated(self) -> bool:
        """Whether the stream ended inside a gzip member or zstd frame (see :class:`LogText`)."""
        return self._state.truncated


def _open_raw(path: str | os.PathLike[str]) -> tuple[io.RawIOBase, Path, _StreamState]:
    file_path = Path(path)
    compression = compression_of(file_path)
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
    return raw, file_path, state


def open_bytes(path: str | os.PathLike[str]) -> LogBytes:
    """Open a log file for streaming reading as bytes, decompressing by its suffix.

    The same streams as :func:`open_text` (which see), without the text decoding: what the
    columnar reader parses.

    Raises:
        StorageError: the file cannot be opened. Reading raises it too when compressed data
            is corrupt (as opposed to cut short).
    """
    return LogBytes(*_open_raw(path))


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
    return LogText(*_open_raw(path))
