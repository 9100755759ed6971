"""The end of a log and pieces of one: parsing that does not start at the banner.

:func:`read_tail` reads the entries among the last bytes of a plain alog (a listing's or a
player's last times, without reading the whole file); :func:`parse_lines` parses text that
starts at a line's start, for scans that resume where they stopped in a growing file.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from fleetlog.errors import StorageError
from fleetlog.storage.alogblocks import PassState, parse_block
from fleetlog.storage.alogfields import line_start, starts_entry
from fleetlog.storage.alogtypes import typed
from fleetlog.storage.columns import SCHEMA, decode_block, polars_module

if TYPE_CHECKING:
    import polars as pl

__all__ = ["parse_lines", "read_tail"]


def read_tail(path: str | os.PathLike[str], size: int) -> pl.DataFrame:
    """Return the entries among the last ``size`` bytes of a plain alog, in file order.

    What a listing or a player needs from the end of a log (its last times) without reading
    the whole file. The first line there is skipped (it may be cut), as are stray lines
    (the tail may start inside a multi-line value), and an entry whose line is still being
    written is not read. ``line`` counts from the first line read, not from the file's start.

    Raises:
        StorageError: the file cannot be read.
    """
    file_path = Path(path)
    try:
        with file_path.open("rb") as file:
            end = file.seek(0, os.SEEK_END)
            start = max(0, end - size)
            file.seek(start)
            data = file.read(end - start)
    except OSError as err:
        msg = f"cannot read {file_path}: {err.strerror or err}"
        raise StorageError(msg) from err
    if start > 0:
        data = data[data.find(b"\n") + 1 :] if b"\n" in data else b""
    pl = polars_module()
    cut = data.rfind(b"\n")
    tail = data[cut + 1 :]
    want = frozenset(("line", "offset", "var", "source", "type", "double", "text", "nlines"))
    columns = [name for name in SCHEMA if name in want]
    if cut < 0:
        return typed(pl, _no_heads(pl), pl.lit(False), 1, None, want).select(columns)
    text, exact = decode_block(data[:cut])
    block = None if exact else data[:cut]
    parsed = parse_block(
        pl,
        text,
        block,
        PassState(),
        None,
        want,
        final=True,
        complete=not tail or tail.startswith(b"%") or starts_entry(tail),
        mark_at_end=False,
        on_drop=lambda: None,
    )
    return parsed.frame.select(columns)


def parse_lines(data: bytes, *, final: bool = False) -> tuple[pl.DataFrame, int]:
    """Parse log text that starts at a line's start; return entries and the bytes they take.

    For scans that resume where they stopped (a growing file): without ``final``, the
    last entry and any cut line are left for the next call (its value may go on), and the
    byte count says where that call starts; with ``final``, the last whole entry is read
    too. Stray lines are ignored. Columns: ``line`` (from 1 at ``data``'s start),
    ``offset``, ``var``, ``source``, ``type``, ``double``, ``text``.
    """
    pl = polars_module()
    want = frozenset(("line", "offset", "var", "source", "type", "double", "text", "nlines"))
    columns = [name for name in SCHEMA if name in want]
    end = data.rfind(b"\n")
    if end < 0:
        return typed(pl, _no_heads(pl), pl.lit(False), 1, None, want).select(columns), 0
    block = data[:end]
    text, exact = decode_block(block)
    raw = None if exact else block
    tail = data[end + 1 :]
    parsed = parse_block(
        pl,
        text,
        raw,
        PassState(),
        None,
        want,
        final=final,
        complete=not tail or tail.startswith(b"%") or starts_entry(tail),
        mark_at_end=False,
        on_drop=lambda: None,
    )
    kept = block.count(b"\n") + 1 - parsed.consumed
    used = len(data) if final else line_start(data, end, kept)
    return parsed.frame.select(columns), min(used, len(data))


def _no_heads(lib: ModuleType) -> pl.DataFrame:
    empty: pl.DataFrame = lib.DataFrame(
        schema={
            "idx": lib.UInt32,
            "l": lib.String,
            "offset": lib.Float64,
            "var": lib.String,
            "source": lib.String,
            "v": lib.String,
            "c": lib.String,
        }
    )
    return empty
