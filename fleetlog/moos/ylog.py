r"""The ``.ylog`` system log: MOOS_DEBUG and MOOS_SYSTEM lines (MOOS_FORMAT.md §4.1).

Pure code: text in, text and :class:`YlogEntry` tuples out.

After the banner (:func:`fleetlog.moos.alog.format_banner`) each line is::

    format(t, ".7g").ljust(10) + " " + key.ljust(20) + " " + src.ljust(20) + " "
        + value.ljust(20) + " \n"

A string value loses every ``\n`` (``\r`` stays); a double is printed ``.7g``. Fields are
left-justified and never truncated, so a long field pushes the next ones right; a line is
read back by its fields' widths and separator spaces, which keeps spaces inside the value.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import NamedTuple

from fleetlog.errors import FormatError
from fleetlog.moos.alog import Banner, parse_banner

__all__ = [
    "YlogEntry",
    "YlogFile",
    "format_ylog_line",
    "format_ylog_value",
    "parse_ylog",
    "parse_ylog_line",
]

_TIME_WIDTH = 10
_FIELD_WIDTH = 20
_TIME_RE = re.compile(r"-?[0-9]+(?:\.[0-9]*)?(?:e[-+][0-9]+)?")


def _size(text: str) -> int:
    """Length in bytes of UTF-8, the unit C++ ``setw`` pads to.

    Undecodable bytes carried as ``surrogateescape`` surrogates count as one byte each; any
    other lone surrogate counts as the three bytes ``surrogatepass`` would write.
    """
    if text.isascii():
        return len(text)
    try:
        return len(text.encode("utf-8", "surrogateescape"))
    except UnicodeEncodeError:
        return len(text.encode("utf-8", "surrogatepass"))


def _ljust(text: str, width: int) -> str:
    return text + " " * (width - _size(text))


def format_ylog_value(value: float | str) -> str:
    r"""Return the value as the ylog writes it, unpadded: a double ``.7g``, a string without ``\n``.

    C prints a NaN with its sign bit set as ``-nan``; Python's ``nan`` is corrected for that.
    """
    if isinstance(value, str):
        return value.replace("\n", "")
    if math.isnan(value):
        return "-nan" if math.copysign(1.0, value) < 0 else "nan"
    return format(value, ".7g")


def format_ylog_line(offset: float, key: str, src: str, value: float | str) -> str:
    r"""Return one ylog line, ending in ``" \n"``.

    Args:
        offset: the message's time minus LOGSTART, in seconds.
        key: ``MOOS_DEBUG`` or ``MOOS_SYSTEM`` (as the publisher spelled it).
        src: the bare source (no aux, no community).
        value: a double, or a string (its ``\n`` are removed).
    """
    return (
        _ljust(format_ylog_value(offset), _TIME_WIDTH)
        + " "
        + _ljust(key, _FIELD_WIDTH)
        + " "
        + _ljust(src, _FIELD_WIDTH)
        + " "
        + _ljust(format_ylog_value(value), _FIELD_WIDTH)
        + " \n"
    )


class YlogEntry(NamedTuple):
    """One ylog line read back.

    Attributes:
        offset: seconds since LOGSTART.
        key: the variable (``MOOS_DEBUG`` or ``MOOS_SYSTEM``).
        source: the publishing app.
        text: the value as written, without its padding to 20 (a double is its ``.7g`` text;
            the file does not say which type it was).
    """

    offset: float
    key: str
    source: str
    text: str


def _field_end(
    line: str, pos: int, width: int, what: str, path: str | None, lineno: int | None
) -> int:
    """Return the index of the separator space after the field that starts at ``pos``.

    The field is a word padded with spaces to ``width`` bytes (as C++ counts), or a longer
    word with no padding.
    """
    end = line.find(" ", pos)
    if end < 0:
        msg = f"ylog line ends inside its {what} field"
        raise FormatError(msg, path, lineno)
    pad = width - _size(line[pos:end])
    if pad > 0:
        if line[end : end + pad] != " " * pad:
            msg = f"ylog {what} field is not padded to {width}"
            raise FormatError(msg, path, lineno)
        end += pad
    if line[end : end + 1] != " ":
        msg = f"ylog {what} field is not followed by a space"
        raise FormatError(msg, path, lineno)
    return end


def parse_ylog_line(line: str, *, path: str | None = None, lineno: int | None = None) -> YlogEntry:
    r"""Split a ylog line into time, key, source and value text.

    The value keeps inner and leading spaces; its padding to 20 bytes is removed (so a value
    that itself ended in spaces and fit in 20 bytes loses them: the file cannot tell).

    Args:
        line: the line, with or without its ``\n``.
        path: the file's name, for error messages.
        lineno: the line's 1-based number, for error messages.

    Raises:
        FormatError: the line is not shaped like a ylog line.
    """
    if line.endswith("\n"):
        line = line[:-1]
    sp = line.find(" ")
    if sp <= 0 or not _TIME_RE.fullmatch(line[:sp]):
        msg = f"ylog line does not start with a time: {line[:40]!r}"
        raise FormatError(msg, path, lineno)
    offset = float(line[:sp])
    pos = _field_end(line, 0, _TIME_WIDTH, "time", path, lineno) + 1
    end = _field_end(line, pos, _FIELD_WIDTH, "key", path, lineno)
    key = line[pos:end].rstrip(" ")
    if not key:
        msg = "ylog line has an empty key"
        raise FormatError(msg, path, lineno)
    pos = end + 1
    end = _field_end(line, pos, _FIELD_WIDTH, "source", path, lineno)
    source = line[pos:end].rstrip(" ")
    rest = line[end + 1 :]
    if not rest.endswith(" "):
        msg = "ylog line does not end with its terminator space"
        raise FormatError(msg, path, lineno)
    field = rest[:-1]
    size = _size(field)
    if size < _FIELD_WIDTH:
        msg = f"ylog value field has {size} bytes, expected at least {_FIELD_WIDTH}"
        raise FormatError(msg, path, lineno)
    text = field.rstrip(" ") if size == _FIELD_WIDTH else field
    return YlogEntry(offset, key, source, text)


@dataclass(frozen=True, slots=True)
class YlogFile:
    r"""A whole ylog read back.

    Attributes:
        banner: the banner at the top.
        entries: the lines after the banner.
        truncated: a last line without ``\n`` (a file cut by a crash), not parsed; empty
            when the file ends cleanly.
    """

    banner: Banner
    entries: tuple[YlogEntry, ...]
    truncated: str = ""


def parse_ylog(text: str, path: str | None = None) -> YlogFile:
    r"""Read a whole ylog: the banner and every line; a cut last line is set aside.

    Lines are split at ``\n`` only: a ``\r`` inside a value is part of it.

    Args:
        text: the file's content.
        path: the file's name, for error messages.

    Raises:
        FormatError: the banner or a complete line is malformed.
    """
    lines = text.split("\n")
    truncated = lines.pop()
    banner = parse_banner(lines, path)
    entries = tuple(
        parse_ylog_line(line, path=path, lineno=index)
        for index, line in enumerate(lines[banner.lines :], start=banner.lines + 1)
    )
    return YlogFile(banner, entries, truncated)
