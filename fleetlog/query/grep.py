"""The remote grep: a session's alog entries filtered as aloggrep/alogclip would, streamed.

The filter (:class:`EntryFilter`) is what a :class:`~fleetlog.wire.query.GrepRequest` asks:
variables by MOOS glob, sources by MOOS glob (on the whole source column or on the process
name before ``:``/``@``, so ``pHelmIvP`` also finds ``pHelmIvP:HELM_VAR_INIT``), a time
window in seconds since LOGSTART (absolute bounds are converted with the file's LOGSTART),
and a limit.

Entries are read with the columnar reader (:class:`~fleetlog.storage.columnar.AlogReader`,
``errors="skip"``: a field log with a garbled line still answers, and the end record counts
what was skipped), in file order, as the low-level reader keeps them. The filter runs before
values are typed: globs are matched once per distinct variable and source (a few hundred in a
log of millions of lines) with the linear-time matcher, and rows are kept by set membership
in Rust. The recorder's process serves greps, so blocks are small (:data:`GREP_BLOCK`): no
step holds the GIL for long and recording never waits on a grep.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.storage.columnar import AlogReader, Batch
from fleetlog.storage.select import Selection
from fleetlog.wire.query import (
    REPLY_TARGET,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    encode_grep_line,
)

__all__ = ["GREP_BLOCK", "EntryFilter", "run_grep"]

#: Decompressed bytes parsed per step in the recorder's process (about 13k lines).
GREP_BLOCK = 1 << 20
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


def _record_lines(batch: Batch) -> list[bytes]:
    """Encode a batch of matches as grep record lines (what encode_grep_line writes)."""
    if not batch.exact:
        kinds = batch.frame["type"].to_list()
        return [
            encode_grep_line(GrepRecord(e.offset, e.key, e.source, _KIND[kind], e.text, e.lineno))
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
        f'[{o},"{k}","{s}","{t}","{x}",{n}]\n'.encode("ascii")
        for o, k, s, t, x, n in zip(offsets, keys, sources, kinds, texts, lines, strict=True)
    ]


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
    with AlogReader(path, errors="skip", block_size=GREP_BLOCK) as reader:
        for batch in reader.frames(_COLUMNS, where=keep):
            if cancel is not None and cancel.is_set():
                msg = "the grep was cancelled (the server is closing)"
                raise StorageError(msg)
            room = request.limit - matched
            if batch.height > room:
                batch = batch.head(room)
                truncated = True
            for line in _record_lines(batch):
                chunk.append(line)
                size += len(line)
                if size >= REPLY_TARGET:
                    emit(b"".join(chunk))
                    chunk, size = [], 0
            matched += batch.height
            if truncated:
                break
        scanned = reader.scanned
        end = GrepEnd(matched, scanned, truncated, reader.skipped, reader.truncated)
    chunk.append(encode_grep_line(end))
    emit(b"".join(chunk))
    return end
