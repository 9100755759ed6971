"""How the query commands show vehicles, sessions and transfers: rich tables and figures."""

from __future__ import annotations

import datetime as dt
import math
import sys
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from fleetlog.moos.units import human_size
from fleetlog.wire.query import LatestInfo, SessionInfo

__all__ = [
    "console",
    "err_console",
    "fleet_table",
    "human_duration",
    "human_size",
    "human_time",
    "part_span",
    "plain",
    "sessions_table",
]


def console() -> Console:
    """The console for results (stdout); plain text when not a terminal.

    Piped output gets a wide page, so a script never sees a session name cut short.
    """
    wide = None if sys.stdout.isatty() else 400
    return Console(highlight=False, width=wide)


def err_console() -> Console:
    """The console for progress and notes (stderr)."""
    return Console(stderr=True, highlight=False)


def plain(text: str, style: str = "") -> Text:
    """Text from a vehicle, shown as it is: no rich markup, control characters made visible.

    A session name or an error message comes from the network; ``[red]`` in it must not
    restyle the terminal, nor an escape sequence reach it.
    """
    shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return Text(shown, style=style)


#: a duration longer than this is not a log's (a hostile or garbled reply): shown as ``-``
_CENTURY = 100 * 365.25 * 86400.0


def human_duration(seconds: float | None) -> str:
    """``3725.2`` → ``1:02:05``; None, NaN or beyond a century → ``-``."""
    if seconds is None or math.isnan(seconds) or seconds >= _CENTURY:
        return "-"
    total = round(max(seconds, 0.0))
    hours, rest = divmod(total, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"


def human_time(epoch: float | None) -> str:
    """LOGSTART as ``2025-06-19 12:04:50Z`` (UTC); ``-`` without one or out of range."""
    if epoch is None:
        return "-"
    try:
        when = dt.datetime.fromtimestamp(epoch, dt.UTC)
    except (OverflowError, OSError, ValueError):
        return "-"  # a warped LOGSTART (MOOSTimeWarp) is not an epoch
    return when.strftime("%Y-%m-%d %H:%M:%SZ")


def fleet_table(
    vehicles: Mapping[str, Collection[str]], latest: Mapping[str, list[LatestInfo]]
) -> Table:
    """The ``fleetlog fleet`` table: each vehicle up, what it runs, its latest session.

    A vehicle that two processes answer for (two recorders after a partition healed) gets
    a row for each, with a SERVER column naming them.
    """
    conflict = any(len(answers) > 1 for answers in latest.values())
    table = Table(box=None, pad_edge=False)
    columns = ["VEHICLE", "UP", "LATEST SESSION", "STATE", "STARTED"]
    for column in [*columns, "SERVER"] if conflict else columns:
        table.add_column(column, no_wrap=True)
    for vehicle in sorted(vehicles):
        services = ",".join(sorted(vehicles[vehicle]))
        answers: list[LatestInfo | None] = [*latest.get(vehicle, [])] or [None]
        for info in answers:
            if info is None:
                row = [vehicle, services, "(does not serve its logs)", "-", "-"]
            elif info.session is None:
                row = [vehicle, services, "(no session)", "-", "-"]
            else:
                state = "writing" if info.writing else "complete"
                if info.synced is False:
                    state += " (clock not synced)"
                row = [vehicle, services, info.session, state, human_time(info.start)]
            if conflict:
                many = len(answers) > 1
                row.append(f"{info.server} (CONFLICT)" if many and info else "")
            table.add_row(*row)
    return table


def sessions_table(sessions: list[SessionInfo], latest: str | None) -> Table:
    """The ``fleetlog sessions V`` table, oldest first; the latest marked ``*``."""
    table = Table(box=None, pad_edge=False)
    split = any((info.part or 1) > 1 for info in sessions)
    noted = any(info.notes or info.tags for info in sessions)
    columns = ["", "SESSION", "STARTED", "DURATION", "VARS", "FILES", "SIZE", "STATE"]
    columns += ["PART"] if split else []
    columns += ["NOTES"] if noted else []
    for column in columns:
        table.add_column(column, no_wrap=column != "NOTES")
    for info in sessions:
        start, duration = part_span(info)
        row: list[str | Text] = [
            "*" if info.name == latest else "",
            plain(info.name),
            human_time(start),
            human_duration(duration),
            "-" if info.variables is None else str(info.variables),
            str(len(info.files)),
            human_size(info.size),
            session_state(info),
        ]
        if split:
            row.append("-" if info.part is None else str(info.part))
        if noted:
            row.append(plain(notes_text(info.notes, info.tags)))
        table.add_row(*row)
    return table


def part_span(info: SessionInfo) -> tuple[float | None, float | None]:
    """When a session began and how long it lasted, as a table shows them.

    A split's later part keeps its mission's LOGSTART (so its times go on from the part
    before); shown as such, every part would seem to start with the mission and last longer
    than the last. A later part is shown from when it opened, for as long as it ran.
    """
    start, duration, opened = info.start, info.duration, info.opened
    if (info.part or 1) > 1 and opened is not None and start is not None:
        end = None if duration is None else start + duration
        return opened, None if end is None else max(0.0, end - opened)
    return start, duration


def mission_text(meta: Mapping[str, Any]) -> str | None:
    """``part 2 of mission 3f2a…; notes: site=bay #trial`` from a metadata file's JSON, if any.

    The file may be anything (a log from elsewhere): fields of the wrong type are left out.
    """
    parts = []
    part, mission = meta.get("part"), meta.get("mission_id")
    if isinstance(part, int) and not isinstance(part, bool) and isinstance(mission, str):
        parts.append(f"part {part} of mission {mission[:12]}")
    notes = meta.get("notes")
    tags = meta.get("tags")
    notes = {
        k: v for k, v in (notes.items() if isinstance(notes, dict) else ()) if isinstance(v, str)
    }
    tags = [t for t in (tags if isinstance(tags, list) else ()) if isinstance(t, str)]
    if notes or tags:
        parts.append("notes: " + notes_text(notes, tags, width=400))
    return "; ".join(parts) or None


def notes_text(notes: Mapping[str, str], tags: Sequence[str], width: int = 60) -> str:
    """``site=bay, crew=2 #trial #night``, cut to about ``width`` characters."""
    text = ", ".join(f"{k}={v}" for k, v in notes.items())
    if tags:
        text = (text + " " if text else "") + " ".join(f"#{t}" for t in tags)
    return text if len(text) <= width else text[: width - 1] + "…"


def session_state(info: SessionInfo) -> str:
    """``writing``, ``closed``, ``cut`` (its recorder died), or ``complete`` (no metadata)."""
    if not info.complete:
        text = "writing"
    elif info.state in ("closed", "cut"):
        text = info.state
    else:
        text = "complete"
    return text + (" (clock not synced)" if info.synced is False else "")


def clock_warning(vehicle: str, unsynced: list[str]) -> str | None:
    """The warning for sessions recorded on a clock that was not synchronised, if any."""
    if not unsynced:
        return None
    some = ", ".join(unsynced[:3]) + (f" and {len(unsynced) - 3} more" if len(unsynced) > 3 else "")
    return (
        f"{vehicle}'s clock was not synchronised when {len(unsynced)} session(s) opened"
        f" ({some}): their absolute times may be off, and merging them with other vehicles"
        " by time may mislead"
    )
