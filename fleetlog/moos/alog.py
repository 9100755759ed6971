r"""The ``.alog`` text format: banner and entry lines, written and read back (MOOS_FORMAT.md §2).

Pure code: strings in, strings and :class:`Entry` objects out. The same line format serves the
``.xlog`` (§2.5); the banner serves the ``.slog``, ``.ylog`` and ``._moos`` too (§2.1).

Reading entries back (§12's reader rule) is the columnar reader's work,
:mod:`fleetlog.storage.columnar`; what stays here is the banner and the binary reference,
which are parsed one at a time.
"""

from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass
from typing import NamedTuple

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import NAMES_CACHED

__all__ = [
    "BANNER_RULE",
    "DATATYPE_MARKING",
    "Banner",
    "BinaryRef",
    "Entry",
    "LineFormatter",
    "Variant",
    "format_banner",
    "format_binary_ref",
    "format_double",
    "format_entry",
    "format_logstart",
    "format_time",
    "parse_banner",
    "parse_binary_ref",
    "source_field",
    "split_source",
]

BANNER_RULE = "%" * 59
DATATYPE_MARKING = "%% DATATYPE MARKING ON"
_BINARY_OPEN = "<MOOS_BINARY>"
_BINARY_CLOSE = "</MOOS_BINARY>"


class Variant(enum.Enum):
    """The two on-disk variants of pLogger (§2.3)."""

    #: MOOS-IvP's bundled pLogger (2021 on): 5 decimals for times, LOGSTART ``%.16g``.
    IVP = "ivp"
    #: themoos essential-moos pLogger: 3 decimals for times, LOGSTART ``%.12g``.
    EM = "em"

    @property
    def time_decimals(self) -> int:
        """Decimals of the entry time column."""
        return 5 if self is Variant.IVP else 3

    @property
    def logstart_digits(self) -> int:
        """Significant digits of the banner's LOGSTART value."""
        return 16 if self is Variant.IVP else 12


@dataclass(frozen=True, slots=True)
class BinaryRef:
    """Where a binary value's bytes live in the ``.blog`` (§2.6)."""

    file: str
    offset: int
    size: int


class Entry(NamedTuple):
    """One logged message as read from an alog line (or lines).

    A named tuple: the reader makes millions of them, and a tuple is five times cheaper to
    make than a frozen dataclass.

    Attributes:
        offset: seconds since LOGSTART (the banner's value), as written.
        key: the MOOS variable name.
        source: the source field as written: ``src[:aux][@community]``.
        value: a float for doubles, a str for strings, a :class:`BinaryRef` for binary values.
        text: the value exactly as written, without MarkDataType marker, double padding or
            terminator space (for a binary value, the ``<MOOS_BINARY>`` tag).
        lineno: the 1-based line number where the entry starts.
    """

    offset: float
    key: str
    source: str
    value: float | str | BinaryRef
    text: str
    lineno: int = 0


@dataclass(frozen=True, slots=True)
class Banner:
    """The header pLogger writes at the top of alog, slog, ylog and ``._moos`` files."""

    log_file: str
    opened: str
    logstart: float
    logstart_text: str
    mark_data_type: bool
    lines: int


# --------------------------------------------------------------------------------------------
# Writing


def format_logstart(logstart: float, variant: Variant = Variant.IVP) -> str:
    """Return LOGSTART as pLogger prints it: ``%.16g`` (IVP) or ``%.12g`` (EM), no padding."""
    return f"{logstart:.{variant.logstart_digits}g}"


def format_banner(
    log_file: str,
    logstart: float,
    opened: str,
    *,
    variant: Variant = Variant.IVP,
    mark_data_type: bool = False,
    left_logstart: bool = False,
) -> str:
    r"""Return the 5-line (6 with MarkDataType) banner, each line ending in ``\n``.

    Args:
        log_file: the full file name as pLogger builds it (``dir + "/" + root + ".alog"``).
        logstart: the session's LOGSTART.
        opened: the ``FILE OPENED ON`` text, ctime layout, without newline.
        variant: which pLogger's LOGSTART precision to use.
        mark_data_type: add the ``%% DATATYPE MARKING ON`` line.
        left_logstart: left-justify LOGSTART (pLogger's slog/ylog after a restart, §2.1).
    """
    value = format_logstart(logstart, variant)
    padded = value.ljust(20) if left_logstart else value.rjust(20)
    lines = [
        BANNER_RULE,
        "%% LOG FILE:       " + log_file,
        "%% FILE OPENED ON  " + opened,
        "%% LOGSTART        " + padded,
    ]
    if mark_data_type:
        lines.append(DATATYPE_MARKING)
    lines.append(BANNER_RULE)
    return "\n".join(lines) + "\n"


def format_time(offset: float, variant: Variant = Variant.IVP) -> str:
    """Return the entry time column's text, unpadded."""
    return f"{offset:.{variant.time_decimals}f}"


def format_double(value: float, precision: int = 5) -> str:
    """Return a double value as pLogger writes it: ``%.Nf`` left-justified to 12.

    C++ prints NaN as ``nan`` or ``-nan`` and infinities as ``inf``/``-inf``; Python agrees
    except for the sign of NaN, which is mirrored here.
    """
    if math.isnan(value):
        text = "-nan" if math.copysign(1.0, value) < 0 else "nan"
    else:
        text = f"{value:.{precision}f}"
    return text.ljust(12)


def format_binary_ref(file: str, offset: int, size: int) -> str:
    """Return the alog value that points into the ``.blog``."""
    return f"{_BINARY_OPEN}File={file},Offset={offset},Bytes={size}{_BINARY_CLOSE}"


def source_field(
    src: str,
    aux: str = "",
    community: str = "",
    *,
    log_aux: bool = False,
    mark_external: bool = False,
    own_community: str = "",
) -> str:
    """Build the source column: ``src[:aux][@community]`` per LogAuxSrc and community marking."""
    field = src
    if log_aux and aux:
        field += ":" + aux
    if mark_external and community and community != own_community:
        field += "@" + community
    return field


def split_source(field: str) -> tuple[str, str, str]:
    """Split a source column into ``(src, aux, community)``.

    The community is what follows the last ``@``; the aux what follows the first ``:`` (the
    MOOS-IvP tools split there too).
    """
    community = ""
    if "@" in field:
        field, community = field.rsplit("@", 1)
    src, _, aux = field.partition(":")
    return src, aux, community


def format_entry(
    offset: float,
    key: str,
    source: str,
    value_text: str,
    *,
    variant: Variant = Variant.IVP,
    binary: bool = False,
) -> str:
    r"""Return one entry line (or several, for a multi-line string) ending in ``\n``.

    ``value_text`` is the value part as it goes on disk: a padded double, a raw string (with
    any MarkDataType marker already in front), or a binary reference.
    """
    head = f"{format_time(offset, variant).ljust(15)} {key.ljust(20)} {source.ljust(15)} "
    if binary:
        return head + value_text + "\n"
    return head + value_text + " \n"


class LineFormatter:
    """Formats entry lines fast, caching the padded key/source prefix per pair.

    The recorder formats tens of thousands of lines a second; the key and source columns
    repeat, so their padded text is built once, and a double's whole line is one ``%``
    operation (``%-12.Nf`` is ``format_double``'s text for every value but NaN).
    """

    __slots__ = (
        "_double_line",
        "_double_precision",
        "_mark_data_type",
        "_prefixes",
        "_time_fmt",
        "variant",
    )

    def __init__(
        self,
        variant: Variant = Variant.IVP,
        double_precision: int = 5,
        *,
        mark_data_type: bool = False,
    ) -> None:
        self.variant = variant
        self._double_precision = double_precision
        self._mark_data_type = mark_data_type
        self._time_fmt = f"%-15.{variant.time_decimals}f "
        self._prefixes: dict[tuple[str, str], str] = {}
        self._double_line = ""
        self._compile()

    def _compile(self) -> None:
        marker = "D:" if self._mark_data_type else ""
        self._double_line = f"{self._time_fmt}%s{marker}%-12.{self._double_precision}f \n"

    @property
    def double_precision(self) -> int:
        """Decimals of double values (DoublePrecision)."""
        return self._double_precision

    @double_precision.setter
    def double_precision(self, value: int) -> None:
        self._double_precision = value
        self._compile()

    @property
    def mark_data_type(self) -> bool:
        """Put pLogger's ``D:``/``S:`` markers in front of values (MarkDataType)."""
        return self._mark_data_type

    @mark_data_type.setter
    def mark_data_type(self, value: bool) -> None:
        self._mark_data_type = value
        self._compile()

    def _prefix(self, key: str, source: str) -> str:
        pair = (key, source)
        prefix = self._prefixes.get(pair)
        if prefix is None:
            prefix = f"{key.ljust(20)} {source.ljust(15)} "
            if len(self._prefixes) > NAMES_CACHED:  # bound the cache against key floods
                self._prefixes.clear()
            self._prefixes[pair] = prefix
        return prefix

    def double(self, offset: float, key: str, source: str, value: float) -> str:
        """Return the line for a double value."""
        prefix = self._prefixes.get((key, source)) or self._prefix(key, source)
        if value == value:  # not NaN, whose sign only format_double mirrors
            return self._double_line % (offset, prefix, value)
        text = format_double(value, self._double_precision)
        if self._mark_data_type:
            text = "D:" + text
        return self._time_fmt % offset + prefix + text + " \n"

    def string(self, offset: float, key: str, source: str, value: str) -> str:
        """Return the line(s) for a string value, written verbatim."""
        if self._mark_data_type:
            value = "S:" + value
        return self._time_fmt % offset + self._prefix(key, source) + value + " \n"

    def binary(self, offset: float, key: str, source: str, ref: BinaryRef) -> str:
        """Return the line for a binary value stored in the ``.blog``."""
        tag = format_binary_ref(ref.file, ref.offset, ref.size)
        return self._time_fmt % offset + self._prefix(key, source) + tag + "\n"

    def prefix(self, offset: float, key: str, source: str) -> str:
        """Return the time, key and source columns with their spaces (the blog record head)."""
        return self._time_fmt % offset + self._prefix(key, source)

    def line_formats(self, key: str, source: str) -> tuple[str, str]:
        """Return the ``%`` formats of a double's and a string's line for this key and source.

        ``double_fmt % (offset, value)`` is :meth:`double`'s line for every value but NaN,
        and ``string_fmt % (offset, value)`` is :meth:`string`'s (the recorder's fast lane
        formats a whole line in one step with them).
        """
        head = self._time_fmt + self._prefix(key, source).replace("%", "%%")
        double_marker, string_marker = ("D:", "S:") if self._mark_data_type else ("", "")
        return (
            f"{head}{double_marker}%-12.{self._double_precision}f \n",
            f"{head}{string_marker}%s \n",
        )


# --------------------------------------------------------------------------------------------
# Reading

_BINARY_RE = re.compile(r"<MOOS_BINARY>File=(.*),Offset=(-?[0-9]+),Bytes=([0-9]+)</MOOS_BINARY>")


def parse_binary_ref(text: str) -> BinaryRef | None:
    """Return the reference in a ``<MOOS_BINARY>`` value, or None if ``text`` is not one."""
    match = _BINARY_RE.fullmatch(text)
    if match is None:
        return None
    return BinaryRef(match.group(1), int(match.group(2)), int(match.group(3)))


def parse_banner(lines: list[str], path: str | None = None) -> Banner:
    r"""Parse the banner at the top of a bannered file.

    Args:
        lines: the file's first lines, without ``\n`` (at least the banner's).
        path: the file's name, for error messages.

    Raises:
        FormatError: the lines are not a pLogger banner.
    """
    if not lines or lines[0] != BANNER_RULE:
        msg = f"expected a banner line of 59 '%', got {lines[0][:40]!r}" if lines else "empty"
        raise FormatError(msg, path, 1)
    fields: dict[str, str] = {}
    mark = False
    for index, line in enumerate(lines[1:], start=2):
        if line == BANNER_RULE:
            if "LOGSTART" not in fields:
                msg = "banner has no LOGSTART line"
                raise FormatError(msg, path, index)
            text = fields["LOGSTART"].strip()
            try:
                logstart = float(text)
            except ValueError:
                msg = f"LOGSTART {text!r} is not a number"
                raise FormatError(msg, path, index) from None
            return Banner(
                fields.get("LOG FILE", ""),
                fields.get("FILE OPENED ON", ""),
                logstart,
                text,
                mark,
                index,
            )
        if line == DATATYPE_MARKING:
            mark = True
        elif line.startswith("%% LOG FILE:"):
            fields["LOG FILE"] = line[len("%% LOG FILE:") :].strip(" ")
        elif line.startswith("%% FILE OPENED ON"):
            fields["FILE OPENED ON"] = line[len("%% FILE OPENED ON") :].strip(" ")
        elif line.startswith("%% LOGSTART"):
            fields["LOGSTART"] = line[len("%% LOGSTART") :]
        elif not line.startswith("%"):
            msg = "banner ends before its closing line of 59 '%'"
            raise FormatError(msg, path, index)
    msg = "banner is not closed by a line of 59 '%'"
    raise FormatError(msg, path, len(lines))
