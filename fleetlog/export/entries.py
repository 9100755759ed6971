"""One table of entries under every export: the columnar reader's batches, renamed and typed.

Every format writes these columns (:data:`COLUMNS`), one row per alog entry:

=========  =======  ========================================================================
time       Float64  absolute seconds (LOGSTART + offset); null without a usable banner
offset     Float64  seconds since LOGSTART, as written
variable   String   the MOOS variable
source     String   the process that posted it (the source column before ``:`` and ``@``)
aux        String   its aux source (after ``:``; empty without one)
community  String   the community pLogger marked it with (after ``@``; empty without one)
type       String   ``double``, ``string`` or ``binary``
double     Float64  the value of a double (NaN and infinities kept), else null
string     String   the value of a string; for a binary, its ``<MOOS_BINARY>`` reference
binary     Binary   a binary's bytes from the ``.blog``; null if they cannot be read
=========  =======  ========================================================================

Strings are UTF-8: bytes of the log that are not become U+FFFD (counted in
:attr:`Tally.not_utf8`). A binary payload that cannot be read (``Offset=-1`` after a
pLogger restart, a blog cut short, a reference outside the session) leaves ``binary`` null
and is counted in :attr:`Tally.payloads_missing`; nothing is dropped silently.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from fleetlog.errors import FleetlogError
from fleetlog.moos.alog import Entry, parse_binary_ref
from fleetlog.storage.columnar import AlogReader, Errors
from fleetlog.storage.select import Selection

if TYPE_CHECKING:
    import polars as pl

    from fleetlog.export.sources import Source

__all__ = ["COLUMNS", "Select", "Tally", "entry_frames"]

#: Which entries to keep: one selection, or one per log (absolute times need its LOGSTART).
Select = Selection | Callable[["Source"], Selection | None] | None

#: The export columns and their polars types, in order.
COLUMNS: dict[str, str] = {
    "time": "Float64",
    "offset": "Float64",
    "variable": "String",
    "source": "String",
    "aux": "String",
    "community": "String",
    "type": "String",
    "double": "Float64",
    "string": "String",
    "binary": "Binary",
}
_READ = ("time", "offset", "var", "source", "src", "aux", "type", "double", "text")
#: What is read when the consumer splits each distinct source itself (no per-row split).
_READ_WHOLE = ("time", "offset", "var", "source", "type", "double", "text")


@dataclass
class Tally:
    """What reading the sources met, for the command to report.

    Attributes:
        entries: entries exported.
        skipped: lines the reader skipped (neither entries nor comments; a bad banner).
        truncated: logs that were cut (a crash, or still being written).
        not_utf8: entries whose strings held bytes that are not UTF-8 (now U+FFFD).
        payloads_missing: binary entries whose bytes could not be read from the blog.
        no_logstart: logs without a usable banner (their ``time`` is null).
    """

    entries: int = 0
    skipped: int = 0
    truncated: list[str] = field(default_factory=list)
    not_utf8: int = 0
    payloads_missing: int = 0
    no_logstart: list[str] = field(default_factory=list)

    def warnings(self) -> list[str]:
        """One sentence per thing the user should know."""
        out = [
            f"{name}: the log was cut (a crash, or still being written)" for name in self.truncated
        ]
        out += [
            f"{name}: no usable banner, so absolute times are unknown" for name in self.no_logstart
        ]
        if self.skipped:
            out.append(f"{self.skipped} line(s) were neither entries nor comments and were skipped")
        if self.not_utf8:
            out.append(f"{self.not_utf8} entries held bytes that are not UTF-8 (shown as U+FFFD)")
        if self.payloads_missing:
            out.append(
                f"{self.payloads_missing} binary payload(s) could not be read from their .blog"
                " (exported without their bytes)"
            )
        return out


def _payloads(reader: AlogReader, frame: pl.DataFrame, tally: Tally) -> list[bytes | None]:
    out: list[bytes | None] = []
    for kind, text, offset, var, source in frame.select(
        "type", "text", "offset", "var", "source"
    ).iter_rows():
        if kind != "binary":
            out.append(None)
            continue
        ref = parse_binary_ref(text)
        try:
            if ref is None:
                raise FleetlogError(text)  # noqa: TRY301 - one path for every unreadable one
            out.append(reader.read_binary(Entry(offset, var, source, ref, text)))
        except FleetlogError:
            tally.payloads_missing += 1
            out.append(None)
    return out


def entry_frames(
    source: Source,
    tally: Tally,
    *,
    errors: Errors = "skip",
    selection: Select = None,
    payloads: bool = True,
    split: bool = True,
) -> Iterator[pl.DataFrame]:
    """Yield a log's entries as frames of :data:`COLUMNS`, in file order.

    Args:
        source: the log.
        tally: counts what was met (updated as frames are yielded).
        errors: the reader's error policy.
        selection: keep only these variables, sources and times (or a function of the
            log that says which).
        payloads: read binary payloads from the blog (else ``binary`` is null).
        split: split the source column into ``source``, ``aux`` and ``community``. If
            False, ``source`` is the column as written (``src[:aux][@community]``) and there
            is no ``aux`` or ``community``: for a consumer that splits each distinct source
            once rather than every row (:func:`fleetlog.moos.alog.split_source`).

    Raises:
        StorageError: the log cannot be read, or (``errors="raise"``) it is corrupt.
        FormatError: (``errors="raise"``) the log holds stray lines or a bad banner.
    """
    import polars as pl

    if callable(selection) and not isinstance(selection, Selection):
        selection = selection(source)
    where = None if selection is None or selection.everything else selection
    name = str(source.path)
    with AlogReader(source.path, errors=errors) as reader:
        if reader.logstart is None:
            tally.no_logstart.append(name)
        for batch in reader.frames(_READ if split else _READ_WHOLE, where=where):
            frame = batch.frame
            if not frame.height:
                continue
            if not batch.exact:
                tally.not_utf8 += int(
                    frame.select(
                        pl.any_horizontal(
                            pl.col(c).str.contains("\ufffd", literal=True)
                            for c in ("var", "source", "text")
                        ).sum()
                    ).item()
                )
            binary = None
            if payloads and frame["type"].eq("binary").any():
                binary = pl.Series("binary", _payloads(reader, frame, tally), dtype=pl.Binary)
            tally.entries += frame.height
            yield _typed(frame, binary) if split else _whole(frame, binary)
        tally.skipped += reader.skipped
        if reader.truncated:
            tally.truncated.append(name)


def _typed(frame: pl.DataFrame, binary: pl.Series | None) -> pl.DataFrame:
    import polars as pl

    sources = frame["source"].unique()
    communities = sources.str.extract(r"@([^@]*)$").fill_null("")
    # Most logs mark no community: then there is nothing to look up row by row.
    community = (
        pl.col("source").replace_strict(sources, communities, return_dtype=pl.String)
        if communities.str.len_bytes().max()
        else pl.lit("", pl.String)
    )
    out = frame.select(
        "time",
        "offset",
        pl.col("var").alias("variable"),
        pl.col("src").alias("source"),
        "aux",
        community.alias("community"),
        pl.col("type").cast(pl.String),
        "double",
        pl.when(pl.col("type") != "double").then(pl.col("text")).alias("string"),
    )
    return _with_binary(out, binary)


def _whole(frame: pl.DataFrame, binary: pl.Series | None) -> pl.DataFrame:
    import polars as pl

    out = frame.select(
        "time",
        "offset",
        pl.col("var").alias("variable"),
        "source",
        pl.col("type").cast(pl.String),
        "double",
        pl.when(pl.col("type") != "double").then(pl.col("text")).alias("string"),
    )
    return _with_binary(out, binary)


def _with_binary(frame: pl.DataFrame, binary: pl.Series | None) -> pl.DataFrame:
    import polars as pl

    if binary is None:
        return frame.with_columns(pl.lit(None, dtype=pl.Binary).alias("binary"))
    return frame.with_columns(binary)
