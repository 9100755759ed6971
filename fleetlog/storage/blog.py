"""Binary payloads: the ``.blog`` beside an alog, and reading a value's bytes from it."""

from __future__ import annotations

import os
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef, Entry
from fleetlog.storage.decompress import compression_of

__all__ = ["blog_beside", "read_payload"]

_BINARY_RECORD_END = 0x0A


def blog_beside(log: Path) -> Path:
    """Return the ``.blog`` beside a log (``root.blog`` for ``root.alog[.gz|.zst]``)."""
    name = log.name
    if compression_of(log):
        name = name[: -len(log.suffix)]
    return log.with_name(Path(name).with_suffix(".blog").name)


def read_payload(log: Path, entry: Entry) -> bytes:
    """Return the payload of a binary entry of ``log`` from the ``.blog`` its reference names.

    ``File=`` is a bare file name, relative to the log's directory (§2.6).

    Raises:
        StorageError: the entry is not binary, its reference is unusable (``Offset=-1``
            after a pLogger restart, a path outside the directory, a range past the end
            of the blog or not ending a blog record), or the blog cannot be read. The
            message names the log line, the blog and the offset.
    """
    ref = entry.value
    where = f"{log}:{entry.lineno}: {entry.key}"
    if not isinstance(ref, BinaryRef):
        msg = f"{where} is not a binary value"
        raise StorageError(msg)
    if not ref.file or ref.file in (".", "..") or Path(ref.file).name != ref.file:
        msg = f"{where} refers to {ref.file!r}, which is not a file beside the log"
        raise StorageError(msg)
    blog = log.parent / ref.file
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
