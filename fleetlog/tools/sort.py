"""``fleetlog sort``: a log in time order, as alogsort does it, with a larger window.

pLogger writes in arrival order, and re-delivered values re-appear with their old times
(MOOS_FORMAT.md §2.2). The sort holds back the latest ``window`` entries (alogsort holds
1000) and writes the rest in time order, equal times in file order; an entry displaced by
more than the window is written as soon as it is seen, after later ones, and counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import BinaryIO

from fleetlog.errors import UsageError
from fleetlog.storage.columnar import Errors
from fleetlog.tools.inputs import LogInput

__all__ = ["DEFAULT_WINDOW", "SortResult", "sort_log"]

#: Entries held back by default: a few MB, and far more than pLogger ever displaces.
DEFAULT_WINDOW = 100_000


@dataclass(frozen=True, slots=True)
class SortResult:
    """What a sort did.

    Attributes:
        entries: entries written.
        late: entries written after a later one (displaced by more than the window).
        skipped: lines that were neither entries nor comments (``errors="skip"``).
        truncated: the input was cut.
    """

    entries: int
    late: int
    skipped: int
    truncated: bool


def sort_log(
    log: LogInput, out: BinaryIO, *, window: int = DEFAULT_WINDOW, errors: Errors = "skip"
) -> SortResult:
    """Write the banner and the entries of ``log`` in time order to ``out``.

    Raises:
        StorageError: the input cannot be read, or the output cannot be written.
        FormatError: (``errors="raise"``) a garbled banner or stray lines.
        UsageError: a negative window.
    """
    import polars as pl

    if window < 0:
        msg = f"the sort window must be 0 or more entries, not {window}"
        raise UsageError(msg)
    written = late = 0
    newest = -float("inf")
    held = None
    with log.reader(errors) as reader:
        out.write(reader.banner_bytes)
        for batch in reader.batches(("line", "offset", "raw")):
            held = batch if held is None else pl.concat([held, batch])
            held = held.sort("offset", maintain_order=True)
            ready = held.height - window
            if ready > 0:
                done, held = held.head(ready), held.tail(window)
                late += int((done["offset"] < newest).sum())
                newest = max(newest, float(done["offset"].max()))  # type: ignore[arg-type]
                out.write(b"\n".join(done["raw"].to_list()) + b"\n")
                written += done.height
        if held is not None and held.height:
            late += int((held["offset"] < newest).sum())
            out.write(b"\n".join(held["raw"].to_list()) + b"\n")
            written += held.height
        return SortResult(written, late, reader.skipped, reader.truncated)
