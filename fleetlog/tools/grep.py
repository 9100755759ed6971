"""``fleetlog grep`` and ``fleetlog clip``: an alog's matching entries, as an alog.

aloggrep and alogclip semantics (MOOS_FORMAT.md §7.2): the banner, then every entry whose
variable and source match (MOOS globs) and whose time lies in the window, each written back
byte for byte, continuation lines included. ``first``/``final`` keep only the first or the
last matching entry, as aloggrep's ``--first``/``--final`` do. ``docs/reading.md`` lists
where this differs from the C++ tools.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import BinaryIO

from fleetlog.storage.columnar import Errors
from fleetlog.storage.select import Selection
from fleetlog.tools.inputs import LogInput

__all__ = ["GrepResult", "grep_log"]


@dataclass(frozen=True, slots=True)
class GrepResult:
    """What a grep did.

    Attributes:
        matched: entries written.
        scanned: entries read.
        skipped: lines that were neither entries nor comments (``errors="skip"``).
        truncated: the input was cut.
    """

    matched: int
    scanned: int
    skipped: int
    truncated: bool


def grep_log(
    log: LogInput,
    out: BinaryIO,
    selection: Selection,
    *,
    first: bool = False,
    final: bool = False,
    banner: bool = True,
    errors: Errors = "skip",
) -> GrepResult:
    """Write the banner and the selected entries of ``log`` to ``out``.

    Args:
        log: the input.
        out: a binary stream.
        selection: variables, sources and time window.
        first: keep only the first matching entry.
        final: keep only the last matching entry.
        banner: write the input's banner first.
        errors: the reader's policy for stray lines and corrupt data.

    Raises:
        StorageError: the input cannot be read, or the output cannot be written.
        FormatError: (``errors="raise"``) a garbled banner or stray lines.
        UsageError: both ``first`` and ``final``.
    """
    from fleetlog.errors import UsageError

    if first and final:
        msg = "--first and --final exclude each other"
        raise UsageError(msg)
    matched = 0
    last: bytes | None = None
    with log.reader(errors) as reader:
        if banner:
            out.write(reader.banner_bytes)
        where = None if selection.everything else selection
        for batch in reader.batches(("line", "raw"), where=where):
            raws = batch["raw"]
            if not raws.len():
                continue
            if first:
                out.write(raws[0] + b"\n")
                matched = 1
                break
            if final:
                last = raws[-1]
                continue
            out.write(b"\n".join(raws.to_list()) + b"\n")
            matched += raws.len()
        if final and last is not None:
            out.write(last + b"\n")
            matched = 1
        return GrepResult(matched, reader.scanned, reader.skipped, reader.truncated)
