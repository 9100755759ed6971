"""The remote grep: a session's alog entries filtered as aloggrep/alogclip would, streamed.

The filter (:class:`EntryFilter`) is what a :class:`~fleetlog.wire.query.GrepRequest` asks:
variables by MOOS glob, sources by MOOS glob (on the whole source column or on the process
name before ``:``/``@``, so ``pHelmIvP`` also finds ``pHelmIvP:HELM_VAR_INIT``), a time
window in seconds since LOGSTART (absolute bounds are converted with the file's LOGSTART),
and a limit. Verdicts are cached per variable and per source, because both repeat on
nearly every line.

Entries are read with :class:`~fleetlog.storage.readers.AlogReader` (``errors="skip"``: a
field log with a garbled line still answers, and the end record counts what was skipped),
in file order, as the low-level reader keeps them.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef, Entry, split_source
from fleetlog.moos.patterns import MoosGlob
from fleetlog.storage.readers import AlogReader
from fleetlog.wire.query import (
    REPLY_TARGET,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    encode_grep_line,
)

__all__ = ["EntryFilter", "run_grep"]

_CANCEL_EVERY = 4096


class EntryFilter:
    """Decides which entries a grep request keeps.

    Args:
        request: the request.
        logstart: the log's LOGSTART, to convert absolute time bounds (None without one).

    Raises:
        FormatError: an absolute time bound on a log without LOGSTART.
    """

    def __init__(self, request: GrepRequest, logstart: float | None) -> None:
        self._vars = [MoosGlob(p) for p in request.variables]
        self._sources = [MoosGlob(p) for p in request.sources]
        self.low = request.start.offset(logstart) if request.start else None
        self.high = request.end.offset(logstart) if request.end else None
        self._var_verdicts: dict[str, bool] = {}
        self._source_verdicts: dict[str, bool] = {}

    def _var_ok(self, key: str) -> bool:
        verdict = self._var_verdicts.get(key)
        if verdict is None:
            verdict = not self._vars or any(g.matches(key) for g in self._vars)
            if len(self._var_verdicts) < 65536:
                self._var_verdicts[key] = verdict
        return verdict

    def _source_ok(self, source: str) -> bool:
        verdict = self._source_verdicts.get(source)
        if verdict is None:
            process = split_source(source)[0]
            verdict = not self._sources or any(
                g.matches(source) or g.matches(process) for g in self._sources
            )
            if len(self._source_verdicts) < 65536:
                self._source_verdicts[source] = verdict
        return verdict

    def __call__(self, entry: Entry) -> bool:
        """Return True if the entry is wanted."""
        if self.low is not None and entry.offset < self.low:
            return False
        if self.high is not None and entry.offset > self.high:
            return False
        return self._var_ok(entry.key) and self._source_ok(entry.source)


def _kind(entry: Entry) -> str:
    if isinstance(entry.value, BinaryRef):
        return "b"
    return "d" if isinstance(entry.value, float) else "s"


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
    matched = scanned = 0
    truncated = False
    with AlogReader(path, errors="skip") as reader:
        for entry in reader.entries():
            scanned += 1
            if cancel is not None and not scanned % _CANCEL_EVERY and cancel.is_set():
                msg = "the grep was cancelled (the server is closing)"
                raise StorageError(msg)
            if not keep(entry):
                continue
            if matched >= request.limit:
                truncated = True
                break
            matched += 1
            line = encode_grep_line(
                GrepRecord(
                    entry.offset, entry.key, entry.source, _kind(entry), entry.text, entry.lineno
                )
            )
            chunk.append(line)
            size += len(line)
            if size >= REPLY_TARGET:
                emit(b"".join(chunk))
                chunk, size = [], 0
        end = GrepEnd(matched, scanned, truncated, reader.skipped, reader.truncated)
    chunk.append(encode_grep_line(end))
    emit(b"".join(chunk))
    return end
