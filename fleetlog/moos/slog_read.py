"""Reading a ``.slog`` back: banner, header columns, label blocks and rows (MOOS_FORMAT.md §3).

The layout is described in :mod:`fleetlog.moos.slog`, which writes it. Pure code: text in,
records out; every error is a :class:`~fleetlog.errors.FormatError` naming the line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from fleetlog.errors import FormatError
from fleetlog.moos.alog import Banner, parse_banner
from fleetlog.moos.slog import HEADER_RULE, SLOT_WIDTH, TIME_LINE, encode_text

__all__ = ["SlogColumn", "SlogFile", "SlogLabels", "SlogRow", "parse_row", "parse_slog"]

_DYNAMIC_RE = re.compile(r"DYNAMIC_[0-9]+")
_COLUMN_RE = re.compile(r"%%   \(([0-9]+)\) ")
_NUMBER_RE = re.compile(r"-?(?:[0-9]+(?:\.[0-9]*)?(?:e[-+][0-9]+)?|nan|inf)")
_BRACKETS_RE = re.compile(r"(?: *\[[^\]]*\])* *")
_BRACKET_RE = re.compile(r"\[([^\]]*)\]")


@dataclass(frozen=True, slots=True)
class SlogColumn:
    """One column as the header describes it.

    Attributes:
        number: the ``(k)`` of the header line (TIME is 1, so columns start at 2).
        name: the name as it stands in the header.
        slot: the line is a 64-wide reserved slot (a dynamic column, claimed or not).
        offset: byte offset in the file of the name's first byte.
    """

    number: int
    name: str
    slot: bool
    offset: int

    @property
    def claimed(self) -> bool:
        """A slot whose placeholder name was overwritten by a variable."""
        return self.slot and _DYNAMIC_RE.fullmatch(self.name) is None


@dataclass(frozen=True, slots=True)
class SlogLabels:
    """A label block: the column names and the bracketed time.

    Attributes:
        names: the columns named by the block.
        time_text: the text inside the brackets (``"   0.65"``); empty with no columns.
        lineno: 1-based line number of the block's first line.
    """

    names: tuple[str, ...]
    time_text: str
    lineno: int

    @property
    def offset(self) -> float | None:
        """The block's time, seconds since LOGSTART (None with no columns)."""
        return float(self.time_text) if self.time_text.strip() else None


@dataclass(frozen=True, slots=True)
class SlogRow:
    """A data row: the time and one value per column, None where the row says ``NaN``."""

    offset: float
    values: tuple[float | None, ...]
    lineno: int


@dataclass(frozen=True, slots=True)
class SlogFile:
    r"""A whole slog read back.

    Attributes:
        banner: the banner at the top.
        columns: the header's columns, static and dynamic, in order.
        records: label blocks and rows in file order.
        header_offset: byte offset of the ``%%   (1) TIME`` line.
        truncated: text cut off at the end (a last line without ``\n``, or a label block
            missing its line of times), empty when the file ends cleanly.
    """

    banner: Banner
    columns: tuple[SlogColumn, ...]
    records: tuple[SlogLabels | SlogRow, ...]
    header_offset: int
    truncated: str = ""

    @property
    def rows(self) -> tuple[SlogRow, ...]:
        """The data rows only."""
        return tuple(r for r in self.records if isinstance(r, SlogRow))

    @property
    def labels(self) -> tuple[SlogLabels, ...]:
        """The label blocks only."""
        return tuple(r for r in self.records if isinstance(r, SlogLabels))


def _parse_number(token: str, what: str, path: str | None, lineno: int) -> float:
    if not _NUMBER_RE.fullmatch(token):
        msg = f"slog {what} {token!r} is not a number"
        raise FormatError(msg, path, lineno)
    return float(token)


def _parse_times(rest: str, count: int, path: str | None, lineno: int) -> str:
    if not _BRACKETS_RE.fullmatch(rest):
        msg = f"slog label times must be '[%7.2f]' fields, got {rest.strip()[:40]!r}"
        raise FormatError(msg, path, lineno)
    times: list[str] = _BRACKET_RE.findall(rest)
    if len(times) != count:
        msg = f"slog label block names {count} columns but has {len(times)} times"
        raise FormatError(msg, path, lineno)
    if not times:
        return ""
    if any(t != times[0] for t in times):
        msg = "slog label block times differ between columns"
        raise FormatError(msg, path, lineno)
    try:
        float(times[0])
    except ValueError:
        msg = f"slog label time {times[0]!r} is not a number"
        raise FormatError(msg, path, lineno) from None
    return times[0]


def _parse_header(
    lines: list[str], start: int, position: int, path: str | None
) -> tuple[list[SlogColumn], int, int]:
    """Parse the column header from ``lines[start]``; return columns, next index, position."""
    if start >= len(lines) or lines[start] != TIME_LINE:
        got = lines[start][:40] if start < len(lines) else "end of file"
        msg = f"expected the slog header line {TIME_LINE!r}, got {got!r}"
        raise FormatError(msg, path, start + 1)
    position += len(encode_text(lines[start])) + 1
    columns: list[SlogColumn] = []
    index = start + 1
    while True:
        if index >= len(lines):
            msg = "slog header is not closed by a line of 56 '%'"
            raise FormatError(msg, path, index)
        line = lines[index]
        if line == HEADER_RULE:
            return columns, index + 1, position + len(line) + 1
        match = _COLUMN_RE.match(line)
        number = len(columns) + 2
        if match is None or int(match.group(1)) != number:
            msg = f"expected slog header line '%%   ({number}) NAME', got {line[:40]!r}"
            raise FormatError(msg, path, index + 1)
        body = line[match.end() :]
        raw = encode_text(body)
        slot = len(raw) == SLOT_WIDTH and body.endswith(" ")
        name = body.rstrip(" ") if slot else body
        if not name:
            msg = f"slog header column ({number}) has no name"
            raise FormatError(msg, path, index + 1)
        columns.append(SlogColumn(number, name, slot, position + match.end()))
        position += len(encode_text(line)) + 1
        index += 1


def parse_row(line: str, *, path: str | None = None, lineno: int = 0) -> SlogRow:
    r"""Read one data row: its time and values (None for ``NaN``).

    Args:
        line: the row, with or without its ``\n``.
        path: the file's name, for error messages.
        lineno: the row's 1-based line number, kept in the result and used in messages.

    Raises:
        FormatError: a field is not a number (or ``NaN`` for a value).
    """
    tokens = line.split()
    if not tokens or tokens[0][0] not in "0123456789-":
        msg = f"expected a slog row (or label block), got {line[:40]!r}"
        raise FormatError(msg, path, lineno)
    offset = _parse_number(tokens[0], "time", path, lineno)
    values = tuple(
        None if t == "NaN" else _parse_number(t, "value", path, lineno) for t in tokens[1:]
    )
    return SlogRow(offset, values, lineno)


def parse_slog(text: str, path: str | None = None) -> SlogFile:
    r"""Read a whole slog: banner, header columns, label blocks and rows.

    A last line without ``\n`` (a file cut by a crash) is not parsed but returned in
    :attr:`SlogFile.truncated`, as is a label block whose line of times is missing at the end.
    Rows must have as many values as the latest label block has names.

    Args:
        text: the file's content.
        path: the file's name, for error messages.

    Raises:
        FormatError: the text is not a slog (line number and reason in the message).
    """
    lines = text.split("\n")
    truncated = lines.pop()  # "" when the text ends with "\n"
    banner = parse_banner(lines, path)
    position = sum(len(encode_text(line)) + 1 for line in lines[: banner.lines])
    header_offset = position
    columns, index, _ = _parse_header(lines, banner.lines, position, path)
    width = len(columns)
    records: list[SlogLabels | SlogRow] = []
    while index < len(lines):
        line = lines[index]
        lineno = index + 1
        if line.startswith("%% TIME"):
            names = tuple(line[len("%% TIME") :].split())
            if index + 1 >= len(lines):
                truncated = line + "\n" + truncated
                break
            times = lines[index + 1]
            if not times.startswith("%% TIME"):
                msg = "slog label block is missing its line of times"
                raise FormatError(msg, path, lineno + 1)
            time_text = _parse_times(times[len("%% TIME") :], len(names), path, lineno + 1)
            records.append(SlogLabels(names, time_text, lineno))
            width = len(names)
            index += 2
            continue
        row = parse_row(line, path=path, lineno=lineno)
        if len(row.values) != width:
            msg = f"slog row has {len(row.values)} values, the columns are {width}"
            raise FormatError(msg, path, lineno)
        records.append(row)
        index += 1
    return SlogFile(banner, tuple(columns), tuple(records), header_offset, truncated)
