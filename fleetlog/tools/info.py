"""``fleetlog info``: what alogscan says about a log, and more.

Per variable: entries, value characters (alogscan's "Chars"), types, sources, first and last
time, rate, and the longest silence between two of its entries in file order. Per log: the
vehicle, LOGSTART, duration, the fleetlog recorder's gap reports (``PLOGGER_GAP``) and, when
the session has fleetlog's metadata file, its state and clock.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

from fleetlog.storage.columnar import AlogReader, Errors
from fleetlog.tools.inputs import LogInput

__all__ = ["GAP_VARIABLE", "LogInfo", "VariableInfo", "scan_log"]

#: The variable a fleetlog recorder posts its gaps under.
GAP_VARIABLE = "PLOGGER_GAP"
_META = ".fleetlog-session.json"
_MAX_GAP_TEXTS = 100


@dataclass
class VariableInfo:
    """One variable's summary.

    Attributes:
        name: the variable.
        count: its entries.
        chars: the characters of its values (alogscan's "Chars").
        types: entries per type (``double``, ``string``, ``binary``).
        sources: the source columns it came from, sorted.
        first: its earliest offset (seconds since LOGSTART).
        last: its latest offset.
        max_gap: the longest time between two of its entries in file order (0 for one).
    """

    name: str
    count: int = 0
    chars: int = 0
    types: dict[str, int] = field(default_factory=dict)
    sources: list[str] = field(default_factory=list)
    first: float = math.inf
    last: float = -math.inf
    max_gap: float = 0.0
    _previous: float | None = None

    @property
    def rate(self) -> float:
        """Entries per second between its first and last entry (0 for one)."""
        span = self.last - self.first
        return (self.count - 1) / span if self.count > 1 and span > 0 else 0.0

    @property
    def type(self) -> str:
        """Its type, or the types joined with ``/`` when it was posted as several."""
        return "/".join(sorted(self.types)) or "-"


@dataclass
class LogInfo:
    """A log's summary.

    Attributes:
        path: the alog.
        vehicle: the vehicle (see :class:`~fleetlog.tools.inputs.LogInput`).
        logstart: LOGSTART, or None without a usable banner.
        entries: entries read.
        first: the earliest offset, or None without entries.
        last: the latest offset, or None.
        variables: per variable, by name.
        gaps: the texts of the recorder's ``PLOGGER_GAP`` entries (at most 100).
        gap_count: how many ``PLOGGER_GAP`` entries there are.
        truncated: the file was cut (a crash, or still being written).
        skipped: lines that were neither entries nor comments, and corrupt compressed data.
        session: the session's fleetlog metadata (state, clock, counters), when present.
    """

    path: str
    vehicle: str
    logstart: float | None
    entries: int = 0
    first: float | None = None
    last: float | None = None
    variables: dict[str, VariableInfo] = field(default_factory=dict)
    gaps: list[str] = field(default_factory=list)
    gap_count: int = 0
    truncated: bool = False
    skipped: int = 0
    session: dict[str, Any] | None = None

    @property
    def duration(self) -> float:
        """Seconds from the earliest to the latest entry."""
        return 0.0 if self.first is None or self.last is None else self.last - self.first

    def to_json(self) -> dict[str, Any]:
        """Return the summary as plain JSON types (what ``--json`` prints)."""
        variables = []
        for var in sorted(self.variables.values(), key=lambda v: v.name):
            item = asdict(var)
            item.pop("_previous", None)
            item["rate"] = var.rate
            item["type"] = var.type
            variables.append(item)
        return {
            "path": self.path,
            "vehicle": self.vehicle,
            "logstart": self.logstart,
            "entries": self.entries,
            "first": self.first,
            "last": self.last,
            "duration": self.duration,
            "truncated": self.truncated,
            "skipped": self.skipped,
            "gap_count": self.gap_count,
            "gaps": self.gaps,
            "session": self.session,
            "variables": variables,
        }


def _session_meta(log: LogInput) -> dict[str, Any] | None:
    path = log.path.parent / _META
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def scan_log(log: LogInput, errors: Errors = "skip") -> LogInfo:
    """Read a whole log once and summarise it.

    Raises:
        StorageError: the file cannot be read (or, under ``errors="raise"``, is corrupt).
        FormatError: (``errors="raise"``) a garbled banner or stray lines.
    """
    import polars as pl

    col = pl.col
    with AlogReader(log.path, errors=errors) as reader:
        info = LogInfo(str(log.path), log.vehicle, reader.logstart)
        stats = info.variables
        for batch in reader.batches(("offset", "var", "source", "type", "text")):
            info.entries += batch.height
            grouped = batch.group_by("var", maintain_order=True).agg(
                count=pl.len(),
                chars=col("text").str.len_chars().sum(),
                first=col("offset").min(),
                last=col("offset").max(),
                head=col("offset").first(),
                tail=col("offset").last(),
                gap=col("offset").diff().max(),
                sources=col("source").unique(),
                types=col("type").cast(pl.String).unique(),
                type_counts=col("type").cast(pl.String).value_counts(),
            )
            for row in grouped.iter_rows(named=True):
                _add(stats, row)
            gaps = batch.filter(col("var") == GAP_VARIABLE)["text"]
            info.gap_count += gaps.len()
            room = _MAX_GAP_TEXTS - len(info.gaps)
            if room > 0:
                info.gaps.extend(gaps.head(room).to_list())
        info.truncated = reader.truncated
        info.skipped = reader.skipped
    firsts = [v.first for v in stats.values()]
    lasts = [v.last for v in stats.values()]
    info.first = min(firsts) if firsts else None
    info.last = max(lasts) if lasts else None
    info.session = _session_meta(log)
    return info


def _add(stats: dict[str, VariableInfo], row: dict[str, Any]) -> None:
    name = row["var"]
    var = stats.get(name)
    if var is None:
        var = stats[name] = VariableInfo(name)
    var.count += row["count"]
    var.chars += row["chars"] or 0
    var.first = min(var.first, row["first"])
    var.last = max(var.last, row["last"])
    gap = row["gap"] if row["gap"] is not None else 0.0
    if var._previous is not None:
        gap = max(gap, row["head"] - var._previous)
    var.max_gap = max(var.max_gap, gap)
    var._previous = row["tail"]
    for item in row["type_counts"]:
        kind = item["type"]
        var.types[kind] = var.types.get(kind, 0) + item["count"]
    sources = set(var.sources)
    sources.update(row["sources"])
    if len(sources) > len(var.sources):
        var.sources = sorted(sources)
