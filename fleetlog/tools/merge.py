"""``fleetlog merge``: several vehicles' logs as one alog in absolute-time order.

Each input is put in time order with a bounded window (as ``fleetlog sort``), then the inputs
are merged by absolute time (LOGSTART + offset) onto the earliest LOGSTART, whose banner the
output carries. Each line keeps its bytes except its time column, rewritten for the new
LOGSTART, and, with ``mark="source"`` (the default), its source column, which gets
``@VEHICLE`` appended as pLogger marks a message from another community (§2.2
MarkExternalCommunityMessages): the MOOS-IvP tools then split source and vehicle.
``mark="none"`` leaves the source as it was (the vehicles are then only told apart by their
MOOSDB's variables).
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import BinaryIO, Literal

from fleetlog.errors import StorageError, UsageError
from fleetlog.moos.alog import Variant, format_banner
from fleetlog.storage.columnar import AlogReader, Errors
from fleetlog.storage.select import Selection
from fleetlog.tools.inputs import LogInput
from fleetlog.tools.sort import DEFAULT_WINDOW

__all__ = ["MergeResult", "merge_logs"]

Mark = Literal["source", "none"]


@dataclass(frozen=True, slots=True)
class MergeResult:
    """What a merge did.

    Attributes:
        entries: entries written.
        late: entries written after a later one (displaced by more than the window).
        logstart: the output's LOGSTART (the earliest input's).
        skipped: lines the inputs' readers skipped.
        truncated: the inputs that were cut.
    """

    entries: int
    late: int
    logstart: float
    skipped: int
    truncated: tuple[str, ...]


def _rows(
    reader: AlogReader, logstart: float, selection: Selection | None, window: int
) -> Iterator[tuple[float, int, int, str, bytes, int, int]]:
    """Yield ``(time, input order, line, var, raw, kpos, spos)`` in time order (windowed)."""
    import polars as pl

    held = None
    where = None if selection is None or selection.everything else selection
    for batch in reader.frames(("line", "offset", "var", "raw"), where=where):
        frame = batch.frame.with_columns(batch.layout().select("kpos", "spos"))
        held = frame if held is None else pl.concat([held, frame])
        held = held.sort("offset", maintain_order=True)
        ready = held.height - window
        if ready > 0:
            done, held = held.head(ready), held.tail(window)
            yield from _tuples(done, logstart)
    if held is not None:
        yield from _tuples(held, logstart)


def _tuples(
    frame: object, logstart: float
) -> Iterator[tuple[float, int, int, str, bytes, int, int]]:
    for line, offset, var, raw, kpos, spos in frame.iter_rows():  # type: ignore[attr-defined]
        yield (logstart + offset, 0, line, var, raw, kpos, spos)


def _tagged(
    rows: Iterator[tuple[float, int, int, str, bytes, int, int]], index: int
) -> Iterator[tuple[float, int, int, str, bytes, int, int]]:
    for row in rows:
        yield (row[0], index, *row[2:])


def _line(
    raw: bytes, offset: float, decimals: int, kpos: int, spos: int, var: str, vehicle: str | None
) -> bytes:
    """Rewrite an entry's time column (and source column, with the vehicle appended)."""
    text = raw.decode("utf-8", "surrogateescape")
    head = (f"{offset:.{decimals}f}".ljust(15) + " ").encode()
    if vehicle is None:
        return head + text[kpos:].encode("utf-8", "surrogateescape")
    source_end = text.index(" ", spos)
    source = text[spos:source_end] + "@" + vehicle
    value_start = max(spos + 15, source_end) + 1
    rest = f"{var.ljust(20)} {source.ljust(15)} " + text[value_start:]
    return head + rest.encode("utf-8", "surrogateescape")


def merge_logs(
    logs: Sequence[LogInput],
    out: BinaryIO,
    *,
    mark: Mark = "source",
    selection: Selection | None = None,
    window: int = DEFAULT_WINDOW,
    errors: Errors = "skip",
    name: str = "merged.alog",
) -> MergeResult:
    """Write the inputs' entries as one alog in absolute-time order.

    Args:
        logs: the inputs (one per vehicle, usually).
        out: a binary stream.
        mark: ``"source"`` appends ``@VEHICLE`` to each source, ``"none"`` leaves it.
        selection: variables, sources and a window (offsets of the merged log) to keep.
        window: entries each input holds back to put itself in order.
        errors: the readers' policy for stray lines and corrupt data.
        name: the file name the banner's ``LOG FILE`` line gives.

    Raises:
        StorageError: an input cannot be read or has no LOGSTART, or the output cannot be
            written.
        UsageError: no inputs, or a negative window.
    """
    if not logs:
        msg = "nothing to merge: give at least one alog or session directory"
        raise UsageError(msg)
    if window < 0:
        msg = f"the sort window must be 0 or more entries, not {window}"
        raise UsageError(msg)
    readers: list[AlogReader] = []
    try:
        for log in logs:
            readers.append(log.reader(errors))
        starts = []
        for log, reader in zip(logs, readers, strict=True):
            if reader.logstart is None:
                msg = f"{log.name}: no usable banner, so its entries have no absolute time"
                raise StorageError(msg)
            starts.append(reader.logstart)
        logstart = min(starts)
        decimals = max(log.time_decimals for log in logs)
        out.write(
            format_banner(
                f"./{name}",
                logstart,
                time.ctime(),
                variant=Variant.IVP if decimals >= 5 else Variant.EM,
            ).encode()
        )
        streams = []
        for index, (reader, start) in enumerate(zip(readers, starts, strict=True)):
            # the window is in the merged log's offsets: shift it to this input's
            local = None if selection is None else selection.shifted(logstart - start)
            streams.append(_tagged(_rows(reader, start, local, window), index))
        written = late = 0
        newest = -float("inf")
        pending: list[bytes] = []
        vehicles = [log.vehicle if mark == "source" else None for log in logs]
        for when, index, _line_no, var, raw, kpos, spos in heapq.merge(*streams):
            if when < newest:
                late += 1
            else:
                newest = when
            pending.append(_line(raw, when - logstart, decimals, kpos, spos, var, vehicles[index]))
            if len(pending) >= 10_000:
                out.write(b"\n".join(pending) + b"\n")
                written += len(pending)
                pending = []
        if pending:
            out.write(b"\n".join(pending) + b"\n")
            written += len(pending)
        skipped = sum(reader.skipped for reader in readers)
        cut = tuple(log.name for log, reader in zip(logs, readers, strict=True) if reader.truncated)
        return MergeResult(written, late, logstart, skipped, cut)
    finally:
        for reader in readers:
            reader.close()
