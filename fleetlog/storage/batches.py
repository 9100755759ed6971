"""A batch of entries: its columns, and its rows as exact :class:`Entry` objects."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from fleetlog.moos.alog import BinaryRef, Entry, parse_binary_ref

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Batch", "to_entries"]

#: Rows turned into Entry objects at a time.
_ENTRY_CHUNK = 1024


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
        return to_entries(self._full, self.exact)

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


def to_entries(frame: pl.DataFrame, exact: bool) -> Iterator[Entry]:
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
