"""The remote grep: a session's alog entries filtered as aloggrep/alogclip would, streamed.

The filter (:class:`EntryFilter`) is what a :class:`~fleetlog.wire.query.GrepRequest` asks:
variables by MOOS glob, sources by MOOS glob (on the whole source column or on the process
name before ``:``/``@``, so ``pHelmIvP`` also finds ``pHelmIvP:HELM_VAR_INIT``), a time
window in seconds since LOGSTART (absolute bounds are converted with the file's LOGSTART),
and a limit.

Entries are read with the columnar reader (:class:`~fleetlog.storage.columnar.AlogReader`,
``errors="skip"``: a field log with a garbled line still answers, and the end record counts
what was skipped), in file order, as the low-level reader keeps them. The filter runs before
values are typed, and most lines are never cut into fields: a line a glob keeps holds the
glob's literal (``NAV_X``), so in a block without continuation lines only the lines holding
one are (:mod:`fleetlog.storage.alogheads`). Globs are matched once per distinct variable and
source (a few hundred in a log of millions of lines) with the linear-time matcher, rows are
kept by set membership in Rust, and the matches are written as JSON lines by one string
kernel a block (:func:`_record_lines`), not one Python object per record. The recorder's
process serves greps, so blocks are small (:data:`GREP_BLOCK`): no step holds the GIL for
long and recording never waits on a grep.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from fleetlog.errors import StorageError
from fleetlog.storage.columnar import AlogReader, Batch
from fleetlog.storage.purity import PurityMemo
from fleetlog.storage.select import Selection
from fleetlog.wire.query import (
    REPLY_TARGET,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    encode_grep_line,
)

if TYPE_CHECKING:
    import polars as pl

__all__ = ["GREP_BLOCK", "PURITY", "EntryFilter", "run_grep"]

#: Decompressed bytes parsed per step in the recorder's process (about 26k lines). Each block
#: costs ~5 ms of fixed work besides its lines: 1 MiB blocks took 1.05 CPU s for a 77 MB log,
#: 2 MiB 0.87, 4 MiB 0.73, for +20 and +55 MiB of peak memory a grep (docs/bench.md §9.2).
GREP_BLOCK = 2 << 20
#: What this process's greps learnt of which ranges of its logs hold entry lines only: a
#: second grep of a closed session cuts only the lines holding its literals, not testing each
#: line again (a quarter of a grep's CPU; docs/bench.md §19).
PURITY = PurityMemo()
_KIND = {"double": "d", "string": "s", "binary": "b"}
_COLUMNS = ("line", "offset", "var", "source", "type", "text")


class EntryFilter(Selection):
    """Decides which entries a grep request keeps (a :class:`Selection` built from it).

    Args:
        request: the request.
        logstart: the log's LOGSTART, to convert absolute time bounds (None without one).

    Raises:
        FormatError: an absolute time bound on a log without LOGSTART.
    """

    def __init__(self, request: GrepRequest, logstart: float | None) -> None:
        low = request.start.offset(logstart) if request.start else None
        high = request.end.offset(logstart) if request.end else None
        super().__init__(request.variables, request.sources, low, high)


_ENCODE = json.JSONEncoder(separators=(",", ":")).encode


def _json_strings(values: list[str]) -> list[str]:
    """Encode strings as JSON (ASCII) in one call of the C encoder, one text per value.

    Inside an encoded string every ``"`` is escaped, so ``","`` only ever separates items.
    """
    if not values:
        return []
    return _ENCODE(values)[2:-2].split('","')


def _json_numbers(values: list[float] | list[int]) -> list[str]:
    """Encode numbers as JSON in one call (no number's text holds a comma)."""
    if not values:
        return []
    return _ENCODE(values)[1:-1].split(",")


#: Characters JSON (ASCII) writes escaped: a value holding none is its own JSON text.
_ESCAPED = r'[^\x20-\x7e]|["\\]'


def _python_lines(batch: Batch) -> list[str]:
    """Encode a batch of matches as grep record lines, one Python object per field."""
    if not batch.exact:
        kinds = batch.frame["type"].to_list()
        return [
            encode_grep_line(
                GrepRecord(e.offset, e.key, e.source, _KIND[kind], e.text, e.lineno)
            ).decode("ascii")
            for e, kind in zip(batch.entries(), kinds, strict=True)
        ]
    frame = batch.frame
    offsets = _json_numbers(frame["offset"].to_list())
    keys = _json_strings(frame["var"].to_list())
    sources = _json_strings(frame["source"].to_list())
    texts = _json_strings(frame["text"].to_list())
    lines = _json_numbers(frame["line"].to_list())
    kinds = [_KIND[kind] for kind in frame["type"].to_list()]
    return [
        f'[{o},"{k}","{s}","{t}","{x}",{n}]\n'
        for o, k, s, t, x, n in zip(offsets, keys, sources, kinds, texts, lines, strict=True)
    ]


def _record_lines(batch: Batch) -> pl.Series:
    """A batch of matches as grep record lines (ASCII text): what encode_grep_line writes.

    Written by one polars string kernel where a field's text is already its JSON (names,
    sources and values with no character JSON escapes; times from 1e-4 to 1e16, where
    polars and Python write a float alike): no Python object per record, so neither the
    time nor the GIL a block takes grows with its matches. The other rows (rare) are
    encoded in Python, as before, and put in their place.
    """
    import polars as pl

    frame = batch.frame
    if not batch.exact or not frame.height:
        return pl.Series("r", _python_lines(batch), dtype=pl.String)
    col = pl.col
    size = col("offset").abs()
    plain = (col("offset") == 0) | ((size >= 1e-4) & (size < 1e16))
    for name in ("var", "source", "text"):
        plain = plain & col(name).is_not_null() & ~col(name).str.contains(_ESCAPED)
    kind = (
        pl.when(col("type") == "double")
        .then(pl.lit("d"))
        .when(col("type") == "string")
        .then(pl.lit("s"))
        .otherwise(pl.lit("b"))
    )
    text = pl.concat_str(
        pl.lit("["),
        col("offset").cast(pl.String),
        pl.lit(',"'),
        col("var"),
        pl.lit('","'),
        col("source"),
        pl.lit('","'),
        kind,
        pl.lit('","'),
        col("text"),
        pl.lit('",'),
        col("line").cast(pl.String),
        pl.lit("]\n"),
    )
    out = frame.select(text.alias("r"), plain.alias("plain"))
    if out["plain"].all():
        return out["r"]
    others = out["plain"].not_().arg_true()
    rest = Batch(frame[others], True, frame[others])
    return out["r"].scatter(others, _python_lines(rest))


def _fill(lines: pl.Series, chunk: list[bytes], size: int, emit: Callable[[bytes], None]) -> int:
    """Add lines to the reply being built, sending it each time it reaches REPLY_TARGET.

    The replies end after the same lines as adding the lines one by one would (the first
    that brings the reply to the target), found by a binary search of the running sizes.
    Returns the size of the reply left unsent.
    """
    import polars as pl

    n = lines.len()
    ends = lines.str.len_bytes().cast(pl.Int64).cum_sum()
    start = base = 0
    while start < n:
        at = int(ends.search_sorted(base + REPLY_TARGET - size, side="left"))
        if at >= n:
            chunk.append(lines.slice(start).str.join("").cast(pl.Binary).item())
            return size + int(ends[n - 1]) - base
        chunk.append(lines.slice(start, at + 1 - start).str.join("").cast(pl.Binary).item())
        emit(b"".join(chunk))
        chunk.clear()
        size = 0
        base = int(ends[at])
        start = at + 1
    return size


def run_grep(
    path: Path,
    header: GrepHeader,
    request: GrepRequest,
    emit: Callable[[bytes], None],
    cancel: threading.Event | None = None,
) -> GrepEnd:
    """Stream the matching entries of an alog to ``emit`` as JSON-line chunks.

    The first chunk starts with the header, the last ends with the end record; each chunk is
    about :data:`~fleetlog.wire.query.REPLY_TARGET` bytes.

    Args:
        path: the alog (already confined to the log root).
        header: the stream's header (session, LOGSTART, banner, time decimals).
        request: the filter and limit.
        emit: sends one chunk (one reply).
        cancel: stops the scan when set (the server is closing).

    Returns:
        The end record that was sent.

    Raises:
        FormatError: an absolute time bound on a log without LOGSTART.
        StorageError: the alog cannot be read, or ``cancel`` was set.
    """
    keep = EntryFilter(request, header.logstart)
    chunk = [encode_grep_line(header)]
    size = len(chunk[0])
    matched = 0
    truncated = False
    with AlogReader(path, errors="skip", block_size=GREP_BLOCK, purity=PURITY) as reader:
        for batch in reader.frames(_COLUMNS, where=keep):
            if cancel is not None and cancel.is_set():
                msg = "the grep was cancelled (the server is closing)"
                raise StorageError(msg)
            room = request.limit - matched
            if batch.height > room:
                batch = batch.head(room)
                truncated = True
            size = _fill(_record_lines(batch), chunk, size, emit)
            matched += batch.height
            if truncated:
                break
        scanned = reader.scanned
        end = GrepEnd(matched, scanned, truncated, reader.skipped, reader.truncated)
    chunk.append(encode_grep_line(end))
    emit(b"".join(chunk))
    return end
