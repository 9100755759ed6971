"""``fleetlog record``'s options for snapshot mode and the disk's bounds (issue 17).

Kept apart from :mod:`fleetlog.cli.record` (the command itself); the values are checked and
merged over the mission's settings by :mod:`fleetlog.moos.keep_settings`.
"""

from __future__ import annotations

from typing import Annotated

import typer

__all__ = [
    "KeepSessionsOption",
    "MaxLogSizeOption",
    "MinFreeDiskOption",
    "SnapshotAfterOption",
    "SnapshotMemoryOption",
    "SnapshotSecondsOption",
    "SnapshotTriggerOption",
]

_PANEL = "Snapshot and disk"

SnapshotSecondsOption = Annotated[
    str | None,
    typer.Option(
        "--snapshot-seconds",
        metavar="TIME",
        help="Snapshot mode: keep the last TIME (30, 2min) in memory and write nothing"
        " until a SNAPSHOT (PLOGGER_CMD, control, a trigger); 0: off"
        " [default: the mission's SnapshotSeconds].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
SnapshotMemoryOption = Annotated[
    str | None,
    typer.Option(
        "--snapshot-memory",
        metavar="SIZE",
        help="The most memory the snapshot ring holds (256MB); past it the oldest samples"
        " are evicted, counted [default: SnapshotMemory, else 256MB].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
SnapshotAfterOption = Annotated[
    str | None,
    typer.Option(
        "--snapshot-after",
        metavar="TIME",
        help="A snapshot records on for TIME past its trigger [default: SnapshotAfter, else 0].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
SnapshotTriggerOption = Annotated[
    list[str] | None,
    typer.Option(
        "--snapshot-trigger",
        metavar="'VAR == VALUE'",
        help="A SNAPSHOT when VAR changes to VALUE (repeatable; adds to the mission's).",
        rich_help_panel=_PANEL,
    ),
]
MinFreeDiskOption = Annotated[
    str | None,
    typer.Option(
        "--min-free-disk",
        metavar="SIZE",
        help="Stop writing while the disk has less than SIZE free (2GB; 0: only a full"
        " disk stops it); resumes by itself [default: MinFreeDisk, else 0].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
KeepSessionsOption = Annotated[
    int | None,
    typer.Option(
        "--keep-sessions",
        metavar="N",
        help="Keep at most N sessions: acknowledged ones are removed first, then the"
        " oldest; never the current one or one being fetched (0: no bound)"
        " [default: KeepSessions, else no bound].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
MaxLogSizeOption = Annotated[
    str | None,
    typer.Option(
        "--max-log-size",
        metavar="SIZE",
        help="Keep at most SIZE of sessions (50GB), removed as --keep-sessions says"
        " (0: no bound) [default: MaxLogSize, else no bound].",
        show_default=False,
        rich_help_panel=_PANEL,
    ),
]
