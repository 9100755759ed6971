"""Append-only output streams for log files: plain, zstd and gzip, with a flush policy.

Plain files are flushed to the OS by the recorder within 20 ms of a line's arrival. Compressed
streams cannot be flushed that often without wrecking the ratio, so they close a unit at least
once a second: a zstd frame (every complete frame is readable after a crash) or a gzip
``Z_SYNC_FLUSH`` point (what pLogger's zipper does every 2048 bytes).

Text is held in memory as written and encoded once per flush, joined: the recorder writes a
line per sample, and one ``write`` per flush instead of an encode and a buffered write per
line saves about a quarter of :meth:`Recorder.handle <fleetlog.recorder.engine.Recorder.handle>`.
The bytes are the same, and they reach the OS at the same flushes as with a buffered file.
"""

from __future__ import annotations

import contextlib
import os
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO, NoReturn

import zstandard

from fleetlog.errors import StorageError

__all__ = ["GzipStream", "OutStream", "PlainStream", "ZstdStream", "open_stream"]

#: the longest a compressed stream keeps data unreadable on disk: a quarter second, so that
#: with the recorder's other delays a sample is readable after a crash within a second even
#: on a loaded machine (bench/faults.py); it costs zstd up to 10 % in size at 50k lines/s,
#: gzip nothing (bench/compressed_units.py, docs/reliability.md)
COMPRESSED_FLUSH_INTERVAL = 0.25


def _fail(action: str, path: Path, err: OSError) -> NoReturn:
    """Raise the StorageError for an OS failure, naming the file and the reason."""
    reason = err.strerror or str(err)
    msg = f"cannot {action} {path}: {reason}"
    raise StorageError(msg) from err


def _close_quietly(raw: BinaryIO) -> None:
    """Close a file whose stream already failed (the first error is the one reported)."""
    with contextlib.suppress(OSError):
        raw.close()


class OutStream:
    """A log file opened for appending text (UTF-8, surrogates escaped).

    ``write`` only collects the text; it reaches the file at :meth:`flush` or :meth:`close`,
    which raise the write errors.
    """

    path: Path
    #: Append text (kept until the next flush). It is the bound ``append`` of the list of
    #: pending text: a line per sample is the recorder's hot path, and a method would add a
    #: Python call to it.
    write: Callable[[str], None]

    def __init__(self, path: Path) -> None:
        self.path = path
        self._text: list[str] = []
        self.write = self._text.append
        #: lines written to this stream that never became readable in the file (a failed
        #: write); each alog or xlog line is one sample, so the recorder counts them lost
        self.unwritten = 0
        #: the same, per variable (the second field of each line; 1024 names at most)
        self.unwritten_names: dict[str, int] = {}

    def _count_unwritten(self, data: bytes) -> None:
        """Count the lines of ``data`` as never written, by variable (a failure: cold path)."""
        names = self.unwritten_names
        for line in data.split(b"\n"):
            if not line.strip():
                continue
            self.unwritten += 1
            fields = line.split(None, 2)
            if len(fields) > 1:
                name = fields[1].decode("utf-8", "surrogateescape")
                if name in names or len(names) < 1024:
                    names[name] = names.get(name, 0) + 1

    def take_text(self) -> list[str]:
        """Return the text lines waiting for the next flush, and forget them."""
        text = list(self._text)
        self._text.clear()  # in place: ``write`` is its bound append
        return text

    def _take(self) -> bytes:
        """Return the text written since the last call, encoded, and forget it."""
        text = self._text
        if not text:
            return b""
        joined = "".join(text)
        # Cleared before the caller writes it: after a failed write the text is not added
        # again to the next one (the recorder counted its samples lost with that error).
        text.clear()
        try:
            return joined.encode("utf-8", "surrogateescape")
        except UnicodeEncodeError:
            # A surrogate that stands for no byte (never from the wire, which is strict UTF-8)
            return joined.encode("utf-8", "surrogatepass")

    def flush(self, now: float) -> None:
        """Hand what was written to the OS (compressed streams: when their interval is due)."""
        raise NotImplementedError

    def fileno(self) -> int:
        """Return the file's descriptor (for fsync from another thread)."""
        raise NotImplementedError

    def unit_due(self) -> float | None:
        """Return when text flushed but not yet readable is due in a unit (compressed), or None."""
        return None

    def take_wait(self) -> float:
        """Return the longest text waited after its flush to become readable, and reset it.

        Plain files: none (a flush hands it to the OS); compressed ones: until their unit ends.
        """
        return 0.0

    def close(self) -> None:
        """Finish the stream (compressed streams end their frame or gzip member) and close."""
        raise NotImplementedError


class PlainStream(OutStream):
    """An uncompressed file, written with one ``write`` per flush (no second buffer).

    Writing straight to the descriptor means a failed write says exactly how many bytes
    reached the file, so :attr:`unwritten` counts exactly the lines that did not (the last
    one may be cut: readers expect a cut tail).
    """

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC, 0o644)
        except OSError as err:
            _fail("create", path, err)
        #: bytes handed to the OS
        self._size = 0
        self._closed = False

    def _put(self, data: bytes, lines: int) -> None:
        """Write ``data`` (``lines`` lines of text, or 0 for raw bytes) to the file."""
        done = 0
        try:
            while done < len(data):
                done += os.write(self._fd, data[done:] if done else data)
        except OSError as err:
            self._size += done
            if lines:
                # From the line the failure cut (or the first one not written) to the end.
                self._count_unwritten(data[data.rfind(b"\n", 0, done) + 1 :])
            _fail("write", self.path, err)
        self._size += done

    def _spill(self) -> None:
        """Write the pending text (before bytes, offsets or a flush)."""
        lines = len(self._text)
        if lines:
            self._put(self._take(), lines)

    def write_bytes(self, data: bytes) -> None:
        """Append raw bytes (after any text written before them)."""
        self._spill()
        self._put(data, 0)

    def fileno(self) -> int:
        """Return the file's descriptor."""
        return self._fd

    def tell(self) -> int:
        """Return the current size of what was written."""
        self._spill()
        return self._size

    def patch(self, offset: int, data: bytes) -> None:
        """Overwrite bytes already written (the slog's in-place column claim)."""
        self._spill()
        try:
            os.pwrite(self._fd, data, offset)
        except OSError as err:
            _fail("write", self.path, err)

    def flush(self, now: float) -> None:
        """Hand what was written to the OS."""
        self._spill()

    def close(self) -> None:
        """Write what is pending and close."""
        if self._closed:
            return
        self._closed = True
        try:
            self._spill()
        finally:
            try:
                os.close(self._fd)
            except OSError as err:
                _fail("close", self.path, err)


class _CompressedStream(OutStream):
    """A compressed file that makes what it holds readable at least once a second.

    Subclasses say how to feed the compressor (:meth:`_feed`), how to end a readable unit
    (:meth:`_sync`) and how to finish the stream (:meth:`_finish`); each writes its output to
    ``self._raw`` and may raise OSError, which is reported here naming the file.
    """

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        try:
            self._raw: BinaryIO = open(path, "wb")  # noqa: SIM115
        except OSError as err:
            _fail("create", path, err)
        self._dirty = False
        self._last = 0.0
        #: when the oldest text not yet in a complete unit was flushed, and the longest wait
        self._since: float | None = None
        self._wait = 0.0
        #: what was fed since the last complete unit: unreadable if the stream is cut now
        self._fed: list[bytes] = []

    def fileno(self) -> int:
        """Return the file's descriptor."""
        return self._raw.fileno()

    def _feed(self, data: bytes) -> None:
        raise NotImplementedError

    def _sync(self) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        raise NotImplementedError

    def _lost(self, err: OSError, action: str = "write") -> NoReturn:
        """Fail: what was fed since the last complete unit (and is pending) is unreadable."""
        for data in (*self._fed, self._take()):
            self._count_unwritten(data)
        self._fed.clear()
        _fail(action, self.path, err)

    def _spill(self) -> None:
        """Feed the pending text to the compressor (it stays before the next unit's end)."""
        if not self._text:
            return
        data = self._take()
        self._fed.append(data)
        try:
            self._feed(data)
        except OSError as err:
            self._lost(err)
        self._dirty = True

    def flush(self, now: float) -> None:
        """End a readable unit if its interval has passed since the last one."""
        self._spill()
        if not self._dirty:
            return
        if self._since is None:
            self._since = now
        if now - self._last >= COMPRESSED_FLUSH_INTERVAL:
            try:
                self._sync()
                self._raw.flush()
            except OSError as err:
                self._lost(err)
            self._fed.clear()
            self._dirty = False
            self._last = now
            self._wait = max(self._wait, now - self._since)
            self._since = None

    def unit_due(self) -> float | None:
        """Return when the text fed since the last unit is due in one (None: nothing fed)."""
        if not (self._dirty or self._text):
            return None
        return self._last + COMPRESSED_FLUSH_INTERVAL

    def take_wait(self) -> float:
        """Return the longest flushed text waited for its unit to end, and reset it."""
        wait, self._wait = self._wait, 0.0
        return wait

    def close(self) -> None:
        """Finish the stream and close the file."""
        try:
            self._spill()
            self._finish()
            self._raw.flush()
        except OSError as err:
            _close_quietly(self._raw)
            self._lost(err, "close")
        except StorageError:
            _close_quietly(self._raw)
            raise
        self._fed.clear()
        try:
            self._raw.close()
        except OSError as err:
            _fail("close", self.path, err)


class ZstdStream(_CompressedStream):
    """A zstd file made of frames, one closed at least every second."""

    def __init__(self, path: Path, level: int = 3) -> None:
        super().__init__(path)
        self._writer = zstandard.ZstdCompressor(level=level).stream_writer(
            self._raw, closefd=False, write_return_read=True
        )

    def _feed(self, data: bytes) -> None:
        self._writer.write(data)

    def _sync(self) -> None:
        # Every complete frame is readable after a crash.
        self._writer.flush(zstandard.FLUSH_FRAME)

    def _finish(self) -> None:
        if self._dirty:
            self._writer.flush(zstandard.FLUSH_FRAME)
            self._raw.flush()
        self._writer.close()  # type: ignore[no-untyped-call]  # zstandard's stub


class GzipStream(_CompressedStream):
    """A single gzip member with sync-flush points, as pLogger's zipper writes."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self._zip = zlib.compressobj(6, zlib.DEFLATED, 31)

    def _feed(self, data: bytes) -> None:
        self._raw.write(self._zip.compress(data))

    def _sync(self) -> None:
        self._raw.write(self._zip.flush(zlib.Z_SYNC_FLUSH))

    def _finish(self) -> None:
        self._raw.write(self._zip.flush(zlib.Z_FINISH))


def open_stream(path: Path, compression: str) -> OutStream:
    """Create a stream for ``compression`` ``none`` / ``zstd`` / ``gzip``.

    Raises:
        StorageError: the file cannot be created.
    """
    if compression == "zstd":
        return ZstdStream(path)
    if compression == "gzip":
        return GzipStream(path)
    return PlainStream(path)
