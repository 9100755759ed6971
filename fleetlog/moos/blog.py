r"""The ``.blog`` binary log: record layout and payload look-up (MOOS_FORMAT.md §2.6).

Pure code: bytes in, bytes out. A binary message becomes one blog record::

    prefix + payload + b"\n"

where ``prefix`` is the alog line's time, key and source columns with their spaces (53 bytes
when no field overflows; :meth:`fleetlog.moos.alog.LineFormatter.prefix` returns it). The
alog line then ends with ``<MOOS_BINARY>File=<root>.blog,Offset=<N>,Bytes=<M></MOOS_BINARY>``,
where ``N`` is the offset of the payload's first byte. The payload may hold any bytes, ``\n``
included, so a blog is read through the alog's references, never on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetlog.errors import FormatError
from fleetlog.moos.alog import BinaryRef

__all__ = [
    "LOST_OFFSET",
    "BlogRecord",
    "format_blog_record",
    "payload_at",
]

#: The offset pLogger writes when its blog stream is dead (after a LOGGER_RESTART, §6.3).
LOST_OFFSET = -1


@dataclass(frozen=True, slots=True)
class BlogRecord:
    r"""One record to append to the blog, and the reference the alog line carries.

    Attributes:
        data: ``prefix + payload + b"\n"``, to append at the blog's current end.
        ref: the file name, payload offset and size, for
            :meth:`fleetlog.moos.alog.LineFormatter.binary`.
    """

    data: bytes
    ref: BinaryRef


def format_blog_record(prefix: str, payload: bytes, blog_size: int, file: str) -> BlogRecord:
    """Build the record for a binary message appended to a blog of ``blog_size`` bytes.

    Args:
        prefix: the alog line's time, key and source columns with their separator spaces.
        payload: the message's bytes.
        blog_size: the blog's current length (where the record starts).
        file: the blog's bare file name (``<root>.blog``), as the alog names it.

    Raises:
        ValueError: ``blog_size`` is negative.
    """
    if blog_size < 0:
        msg = f"blog size must not be negative, got {blog_size}"
        raise ValueError(msg)
    head = prefix.encode("utf-8", "surrogateescape")
    ref = BinaryRef(file, blog_size + len(head), len(payload))
    return BlogRecord(b"".join((head, payload, b"\n")), ref)


def payload_at(
    blog: bytes | bytearray | memoryview, ref: BinaryRef, *, path: str | None = None
) -> bytes:
    r"""Return the payload that ``ref`` points at in the blog's content.

    A payload that ends exactly at the end of the blog is accepted (a file cut before its
    record's ``\n``); otherwise the byte after it must be the record's ``\n``.

    Args:
        blog: the whole blog (a ``mmap`` works through ``memoryview``).
        ref: the reference from the alog's ``<MOOS_BINARY>`` tag.
        path: the blog's name, for error messages.

    Raises:
        FormatError: the payload was lost (``Offset=-1``), the reference is invalid or runs
            past the end of the blog, or no record ends where the payload should.
    """
    start, size = ref.offset, ref.size
    if start == LOST_OFFSET:
        msg = (
            f"binary payload of {size} bytes was lost: Offset=-1 (pLogger did not reopen "
            f"{ref.file} after a LOGGER_RESTART)"
        )
        raise FormatError(msg, path)
    if start < 0 or size < 0:
        msg = f"invalid binary reference Offset={start},Bytes={size}"
        raise FormatError(msg, path)
    end = start + size
    length = len(blog)
    if end > length:
        msg = (
            f"binary payload Offset={start},Bytes={size} runs past the end of the blog "
            f"({length} bytes)"
        )
        raise FormatError(msg, path)
    view = memoryview(blog)
    if end < length and view[end] != 0x0A:
        msg = (
            f"binary payload Offset={start},Bytes={size} is not followed by a newline: "
            f"the blog does not match the alog"
        )
        raise FormatError(msg, path)
    return bytes(view[start:end])
