"""Writing a ``.slog`` synchronous log (MOOS_FORMAT.md §3): header, labels, rows, dynamic columns.

Reading one back is :mod:`fleetlog.moos.slog_read`. Pure code: text in, text (and in-place
byte patches) out. Nothing here opens a file or reads a clock; the recorder passes every time
as an offset from LOGSTART.

Layout of a slog after its banner (written with :func:`fleetlog.moos.alog.format_banner`)::

    %%   (1) TIME                          <- trailing space
    %%   (2) NAV_X                         <- static columns, no trailing space
    %%   (3) DYNAMIC_0 ...                 <- placeholders, the name left-justified in 64
    %%%%%%%%...                            <- 56 '%'
    %% TIME            NAV_X  ...          <- label block: names, then "[%7.2f]" times
    %% TIME            [   0.61] ...
    0.8137105          10     ...          <- rows: time ".7g", values ".6g" or "NaN"

A dynamic LOG_REQUEST claims the first free placeholder by overwriting its name in place
(:func:`claim_slot`); the file keeps its length. :class:`SlogTable` holds the state the recorder
needs (columns, placeholders, freshness, the row counter) and returns the text to append.

fleetlog's fixes (§12) live in :class:`SlogTable`: a row shows the *newest* value since the
last row, and a NOSYNC LOG_REQUEST does not consume a placeholder. Everything else, including
the label block after rows 1, 31, 61, ... and the counter that survives a restart, is pLogger's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "COLUMN_WIDTH",
    "HEADER_RULE",
    "LABEL_EVERY",
    "SLOT_WIDTH",
    "TIME_LINE",
    "SlogClaim",
    "SlogTable",
    "SlotPatch",
    "claim_slot",
    "dynamic_names",
    "encode_text",
    "format_label_block",
    "format_row",
    "format_slog_header",
    "format_slog_value",
    "slot_offsets",
]

#: Width of every slog column before its separator space (EM ``COLUMN_WIDTH``).
COLUMN_WIDTH = 18
#: Bytes reserved for a placeholder's name in the header (EM ``DYNAMIC_NAME_SPACE``).
SLOT_WIDTH = 64
#: The line of 56 ``%`` that closes the column header.
HEADER_RULE = "%" * 56
#: A label block follows rows 1, 1 + LABEL_EVERY, 1 + 2 * LABEL_EVERY, ...
LABEL_EVERY = 30

#: The header's first line (the TIME column), with pLogger's trailing space.
TIME_LINE = "%%   (1) TIME "
_LABEL_HEAD = "%% TIME".ljust(COLUMN_WIDTH) + " "
_NAN_CELL = "NaN".ljust(COLUMN_WIDTH) + " "


def encode_text(text: str) -> bytes:
    """UTF-8, with undecodable bytes carried as ``surrogateescape`` surrogates restored."""
    try:
        return text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogatepass")


def _ljust(text: str, width: int) -> str:
    """Pad to ``width`` bytes of UTF-8, as C++ ``setw`` does; never truncate."""
    if text.isascii():
        return text.ljust(width)
    return text + " " * (width - len(encode_text(text)))


def format_slog_value(value: float, digits: int = 6) -> str:
    """Return a double as C++ iostreams print it with ``setprecision(digits)`` (``%.<d>g``).

    Python's ``g`` format matches C's, except that C prints a NaN whose sign bit is set as
    ``-nan``; that is mirrored here. Examples: ``1.23457e+08``, ``1e-07``, ``-0``, ``inf``.
    """
    if math.isnan(value):
        return "-nan" if math.copysign(1.0, value) < 0 else "nan"
    return format(value, f".{digits}g")


def dynamic_names(count: int, start: int = 0) -> list[str]:
    """Return the placeholder names ``DYNAMIC_<start>`` ... for ``count`` dynamic columns."""
    return [f"DYNAMIC_{i}" for i in range(start, start + count)]


def _placeholders(dynamic_slots: int | Sequence[str]) -> Sequence[str]:
    if isinstance(dynamic_slots, int):
        return dynamic_names(dynamic_slots)
    return dynamic_slots


def _header_lines(
    static_columns: Sequence[str], placeholders: Sequence[str]
) -> list[tuple[str, bool]]:
    lines = [(TIME_LINE, False)]
    number = 2
    for name in static_columns:
        lines.append((f"%%   ({number}) {name}", False))
        number += 1
    for name in placeholders:
        lines.append((f"%%   ({number}) " + _ljust(name, SLOT_WIDTH), True))
        number += 1
    lines.append((HEADER_RULE, False))
    return lines


def format_slog_header(
    static_columns: Sequence[str], dynamic_slots: int | Sequence[str] = 0
) -> str:
    r"""Return the column header that follows the banner, each line ending in ``\n``.

    Args:
        static_columns: the column names in order (the ``Log =`` variables without NOSYNC, and
            after a restart the claimed dynamic columns too).
        dynamic_slots: the number of placeholders (named ``DYNAMIC_0`` ...), or their names
            (after a restart, the still unclaimed ones, e.g. ``["DYNAMIC_1"]``).

    Returns:
        The ``%%   (1) TIME`` line, one line per column, one 64-wide slot per placeholder and
        the line of 56 ``%``. The label block that pLogger writes next is separate
        (:func:`format_label_block`).
    """
    lines = _header_lines(static_columns, _placeholders(dynamic_slots))
    return "".join(line + "\n" for line, _ in lines)


def slot_offsets(
    static_columns: Sequence[str], dynamic_slots: int | Sequence[str] = 0
) -> tuple[int, ...]:
    """Return the byte offset of each placeholder's name field, from the header's first byte.

    Add the banner's length in bytes to get the offset in the file. The arguments are those
    given to :func:`format_slog_header`.
    """
    offsets: list[int] = []
    position = 0
    for line, is_slot in _header_lines(static_columns, _placeholders(dynamic_slots)):
        data = encode_text(line)
        if is_slot:
            offsets.append(position + data.index(b") ") + 2)
        position += len(data) + 1
    return tuple(offsets)


@dataclass(frozen=True, slots=True)
class SlotPatch:
    """Bytes to write over a slog in place: ``seek(offset)`` then ``write(data)``."""

    offset: int
    data: bytes


def claim_slot(offset: int, name: str) -> SlotPatch:
    r"""Return the in-place patch that renames the placeholder whose name field is at ``offset``.

    The name is left-justified in 63 bytes, so the slot's 64th byte (a space) and its ``\n``
    stay and the file keeps its length. A name longer than 63 bytes is not truncated: it
    overwrites the bytes that follow, as pLogger does (§3.3).

    Args:
        offset: where the slot's name field starts in the file (see :func:`slot_offsets`).
        name: the variable that claims the column.
    """
    data = encode_text(name)
    return SlotPatch(offset, data.ljust(SLOT_WIDTH - 1, b" "))


def format_label_block(names: Sequence[str], offset: float) -> str:
    """Return the two label lines: the column names, then ``[%7.2f]`` of ``offset`` per column.

    Args:
        names: every column, static and claimed first, then the unclaimed placeholders.
        offset: the time of the block, seconds since LOGSTART.
    """
    cell = _ljust(f"[{offset:7.2f}]", COLUMN_WIDTH) + " "
    names_line = _LABEL_HEAD + "".join(_ljust(name, COLUMN_WIDTH) + " " for name in names)
    return names_line + "\n" + _LABEL_HEAD + cell * len(names) + "\n"


def format_row(offset: float, values: Sequence[float | None]) -> str:
    r"""Return one data row: the time ``.7g``, then each value ``.6g`` or ``NaN`` for None.

    Every field is left-justified to 18 and followed by one space, so the row ends with a
    space before its ``\n``.
    """
    parts = [format_slog_value(offset, 7).ljust(COLUMN_WIDTH), " "]
    for value in values:
        if value is None:
            parts.append(_NAN_CELL)
        else:
            parts.append(format_slog_value(value).ljust(COLUMN_WIDTH))
            parts.append(" ")
    parts.append("\n")
    return "".join(parts)


@dataclass(frozen=True, slots=True)
class SlogClaim:
    """What a dynamic LOG_REQUEST does to the slog.

    Attributes:
        patch: the in-place rename of the claimed placeholder, or None when no placeholder was
            claimed (none free, or NOSYNC).
        text: the label block to append (pLogger writes one after every accepted request).
    """

    patch: SlotPatch | None
    text: str


class SlogTable:
    """The recorder's slog state: columns, placeholders, newest values, freshness, row count.

    Drive it like this (every ``offset`` is seconds since LOGSTART)::

        table = SlogTable(["NAV_X", "NAV_Y"], dynamic_slots=2)
        f.write(table.start(banner, offset))        # banner + header + first label block
        table.update("NAV_X", 10.0)                 # every sample of a logged variable
        f.write(table.row(offset))                  # when the period has passed
        claim = table.claim("NAV_SPEED", offset)    # an accepted LOG_REQUEST
        if claim is not None:
            if claim.patch is not None:             # seek, overwrite, back to the end
                f.seek(claim.patch.offset); f.write(claim.patch.data); f.seek(0, 2)
            f.write(claim.text)
        new_f.write(table.restart(new_banner, offset))   # LOGGER_RESTART: a new file

    Patch offsets count bytes of the text as UTF-8 (``surrogateescape``), from the start of
    the text :meth:`start` returned: write the slog in that encoding.

    A row shows, for each column, the newest value given to :meth:`update` since the previous
    row (fleetlog's fix; pLogger showed the oldest of a mail batch), or ``NaN`` when there was
    none or it was a string; then every column is stale again. The row counter is not reset by
    :meth:`restart`, as in pLogger.

    Args:
        columns: the static columns in order; names must be distinct.
        dynamic_slots: how many placeholder columns to reserve (``DynamicSyncLogColumns``).

    Raises:
        ValueError: a column name is empty or given twice.
    """

    __slots__ = (
        "_base_slots",
        "_columns",
        "_fresh",
        "_known",
        "_placeholders",
        "_rows",
        "_values",
    )

    def __init__(self, columns: Sequence[str], dynamic_slots: int = 0) -> None:
        if len(set(columns)) != len(columns) or not all(columns):
            msg = f"slog columns must be distinct non-empty names, got {list(columns)!r}"
            raise ValueError(msg)
        self._columns: list[str] = list(columns)
        self._known: set[str] = set(columns)
        self._placeholders: list[str] = dynamic_names(dynamic_slots)
        self._values: dict[str, float | None] = {}
        self._fresh: set[str] = set()
        self._rows = 0
        self._base_slots: dict[str, int] | None = None

    @property
    def columns(self) -> tuple[str, ...]:
        """The variables with a column: static ones, then claimed ones in claim order."""
        return tuple(self._columns)

    @property
    def placeholders(self) -> tuple[str, ...]:
        """The unclaimed placeholder names (always the last columns)."""
        return tuple(self._placeholders)

    @property
    def names(self) -> tuple[str, ...]:
        """Every column as a label block names it: columns, then placeholders."""
        return (*self._columns, *self._placeholders)

    @property
    def rows(self) -> int:
        """How many rows have been written, over all sessions."""
        return self._rows

    def start(self, banner: str, offset: float) -> str:
        """Return the start of a new slog file: ``banner``, the header and a label block.

        Claimed columns are listed as static names and the unclaimed placeholders as
        64-wide slots; claim patches from now on refer to this file.

        Args:
            banner: the file's banner text, from :func:`fleetlog.moos.alog.format_banner`.
            offset: the time of the label block, seconds since LOGSTART.
        """
        base = len(encode_text(banner))
        offsets = slot_offsets(self._columns, self._placeholders)
        self._base_slots = {
            name: base + off for name, off in zip(self._placeholders, offsets, strict=True)
        }
        header = format_slog_header(self._columns, self._placeholders)
        return banner + header + format_label_block(self.names, offset)

    def restart(self, banner: str, offset: float) -> str:
        """Return the start of the next session's slog (LOGGER_RESTART); see :meth:`start`.

        Values, freshness and the row counter carry over, as they do in pLogger.
        """
        return self.start(banner, offset)

    def update(self, name: str, value: float | str) -> None:
        """Record a new sample; the newest one before the next row is shown.

        Samples of variables without a column are ignored. A string makes the column show
        ``NaN`` (the slog holds only doubles).
        """
        if name in self._known:
            self._values[name] = None if isinstance(value, str) else float(value)
            self._fresh.add(name)

    def row(self, offset: float, label_offset: float | None = None) -> str:
        """Return the next row, followed by a label block after rows 1, 31, 61, ...

        Args:
            offset: the row's time, seconds since LOGSTART.
            label_offset: the label block's time if one follows (pLogger reads the clock
                again just after the row); defaults to ``offset``.
        """
        fresh = self._fresh
        values = [self._values[name] if name in fresh else None for name in self._columns]
        values.extend(None for _ in self._placeholders)
        text = format_row(offset, values)
        fresh.clear()
        count = self._rows
        self._rows = count + 1
        if count % LABEL_EVERY == 0:
            when = offset if label_offset is None else label_offset
            text += format_label_block(self.names, when)
        return text

    def claim(self, name: str, offset: float, *, nosync: bool = False) -> SlogClaim | None:
        """Handle an accepted dynamic LOG_REQUEST for ``name``.

        Without NOSYNC, the first free placeholder becomes ``name``'s column (renamed in place,
        keeping its position). With NOSYNC nothing is claimed (fleetlog's fix: pLogger wasted
        a placeholder). Either way a label block follows, as in pLogger.

        Args:
            name: the requested variable.
            offset: the label block's time, seconds since LOGSTART.
            nosync: the request said NOSYNC.

        Returns:
            The patch and text, or None when ``name`` already has a column (nothing changes).

        Raises:
            RuntimeError: a placeholder is claimed before :meth:`start` wrote the header.
        """
        if name in self._known or not name:
            return None
        patch = None
        if not nosync and self._placeholders:
            if self._base_slots is None:
                msg = "SlogTable.start() must write the header before a column is claimed"
                raise RuntimeError(msg)
            slot = self._placeholders.pop(0)
            patch = claim_slot(self._base_slots.pop(slot), name)
            self._columns.append(name)
            self._known.add(name)
        return SlogClaim(patch, format_label_block(self.names, offset))
