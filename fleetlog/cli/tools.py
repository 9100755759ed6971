"""``fleetlog info|grep|clip|sort|merge``: the offline alog tools (engines in fleetlog.tools)."""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, BinaryIO

import typer
from rich.table import Table

from fleetlog.cli.app import app
from fleetlog.cli.tables import (
    console,
    err_console,
    human_duration,
    human_time,
    mission_text,
    plain,
)
from fleetlog.errors import UsageError
from fleetlog.storage.columnar import Errors
from fleetlog.storage.select import Selection
from fleetlog.tools import LogInput, grep_log, merge_logs, open_log, scan_log, sort_log
from fleetlog.tools.sort import DEFAULT_WINDOW
from fleetlog.wire.query import TimeBound

__all__ = ["clip", "grep", "info", "merge", "sort"]

Output = Annotated[
    Path | None,
    typer.Option("-o", "--output", metavar="FILE", help="Write the alog here (default: stdout)."),
]
Strict = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Fail on lines that are neither entries nor comments (default: count and go on).",
    ),
]
Sources = Annotated[
    list[str] | None,
    typer.Option(
        "-s", "--source", metavar="GLOB", help="Keep only these sources (MOOS glob; repeatable)."
    ),
]
Variables = Annotated[
    list[str] | None,
    typer.Option(
        "-v", "--var", metavar="GLOB", help="Keep only these variables (MOOS glob; repeatable)."
    ),
]
From = Annotated[
    str | None,
    typer.Option(
        "--from", metavar="T", help="Start: seconds since LOGSTART, or @EPOCH (absolute)."
    ),
]
To = Annotated[
    str | None,
    typer.Option("--to", metavar="T", help="End: seconds since LOGSTART, or @EPOCH (absolute)."),
]


def _errors(strict: bool) -> Errors:
    return "raise" if strict else "skip"


def _bound(text: str | None, name: str) -> TimeBound | None:
    return None if text is None else TimeBound.parse(text, name)


@contextlib.contextmanager
def _output(path: Path | None) -> Iterator[BinaryIO]:
    if path is None:
        yield sys.stdout.buffer
        sys.stdout.buffer.flush()
        return
    try:
        with path.open("wb") as out:
            yield out
    except OSError as err:
        msg = f"cannot write {path}: {err.strerror or err}"
        raise UsageError(msg) from err


def _warn(log: LogInput, skipped: int, truncated: bool) -> None:
    if skipped:
        err_console().print(
            f"{log.name}: {skipped} line(s) were neither entries nor comments and were skipped"
        )
    if truncated:
        err_console().print(f"{log.name}: the log was cut (a crash, or still being written)")


def _split_args(args: list[str]) -> tuple[list[str], list[str]]:
    """Split positionals into inputs (existing files or directories) and keys."""
    logs = [a for a in args if os.path.exists(a)]
    keys = [a for a in args if not os.path.exists(a)]
    return logs, keys


@app.command()
def info(
    logs: Annotated[
        list[str], typer.Argument(metavar="LOG...", help="alogs (.alog, .gz, .zst) or sessions.")
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = False,
    strict: Strict = False,
) -> None:
    """Summarise logs as alogscan does: per variable count, rate, type, sources, times, gaps."""
    reports = [scan_log(open_log(spec), _errors(strict)) for spec in logs]
    if as_json:
        items = [report.to_json() for report in reports]
        typer.echo(json.dumps(items[0] if len(items) == 1 else items, indent=2))
        return
    out = console()
    for report in reports:
        start = report.logstart
        out.print(
            f"[bold]{report.path}[/bold]  vehicle {report.vehicle}  LOGSTART {start}"
            f" ({human_time(start)})  {report.entries:,} entries over"
            f" {human_duration(report.duration)}"
            + ("  [yellow]cut[/yellow]" if report.truncated else "")
            + (f"  {report.skipped} skipped" if report.skipped else "")
        )
        if report.session:
            state = report.session.get("state", "?")
            clock = report.session.get("clock", report.session.get("clock_sync"))
            out.print(f"session state {state}" + (f", clock {clock}" if clock else ""))
            mission = mission_text(report.session)
            if mission:
                out.print(plain(mission))
        if report.gap_count:
            out.print(f"[yellow]{report.gap_count} gap report(s) (PLOGGER_GAP)[/yellow]")
            for text in report.gaps[:10]:
                out.print(f"  {text}")
        table = Table(
            "Variable",
            "Count",
            "Chars",
            "Rate Hz",
            "Type",
            "First",
            "Last",
            "Max gap",
            "Sources",
            box=None,
        )
        for var in sorted(report.variables.values(), key=lambda v: v.name):
            table.add_row(
                var.name,
                f"{var.count:,}",
                f"{var.chars:,}",
                f"{var.rate:.2f}",
                var.type,
                f"{var.first:.3f}",
                f"{var.last:.3f}",
                f"{var.max_gap:.3f}",
                ",".join(var.sources[:4]) + (",…" if len(var.sources) > 4 else ""),
            )
        out.print(table)


@app.command()
def grep(
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="LOG KEY...",
            help="An alog or session, then keys (MOOS globs) matched against the variable or"
            " the source process, as aloggrep's. Several logs are merged by time.",
        ),
    ],
    variables: Variables = None,
    sources: Sources = None,
    start: From = None,
    end: To = None,
    first: Annotated[bool, typer.Option("--first", help="Only the first matching entry.")] = False,
    final: Annotated[bool, typer.Option("--final", help="Only the last matching entry.")] = False,
    output: Output = None,
    strict: Strict = False,
) -> None:
    """Write the matching entries of an alog, banner included, byte for byte (aloggrep)."""
    specs, keys = _split_args(args)
    if not specs:
        msg = f"no such alog or session directory among {', '.join(args)}"
        raise UsageError(msg)
    _select(specs, keys, variables, sources, start, end, output, strict, first=first, final=final)


@app.command()
def clip(
    log: Annotated[str, typer.Argument(metavar="LOG", help="An alog or session directory.")],
    tmin: Annotated[str, typer.Argument(metavar="TMIN", help="Seconds since LOGSTART, or @EPOCH.")],
    tmax: Annotated[str, typer.Argument(metavar="TMAX", help="Seconds since LOGSTART, or @EPOCH.")],
    output: Output = None,
    strict: Strict = False,
) -> None:
    """Write the entries with TMIN <= time <= TMAX, banner included, byte for byte (alogclip)."""
    _select([log], [], None, None, tmin, tmax, output, strict)


def _select(
    specs: list[str],
    keys: list[str],
    variables: list[str] | None,
    sources: list[str] | None,
    start: str | None,
    end: str | None,
    output: Path | None,
    strict: bool,
    *,
    first: bool = False,
    final: bool = False,
) -> None:
    logs = [open_log(spec) for spec in specs]
    low, high = _bound(start, "--from"), _bound(end, "--to")
    if len(logs) > 1:
        if first or final:
            msg = "--first/--final read one log; merge the logs first"
            raise UsageError(msg)
        with logs[0].reader() as reader:
            logstart = reader.logstart
        selection = Selection.of(variables or (), sources or (), low, high, logstart)
        selection = Selection(
            selection.variables, selection.sources, selection.low, selection.high, keys
        )
        _merge(logs, output, selection, "source", DEFAULT_WINDOW, strict)
        return
    with logs[0].reader() as reader:
        logstart = reader.logstart
    base = Selection.of(variables or (), sources or (), low, high, logstart)
    selection = Selection(base.variables, base.sources, base.low, base.high, keys)
    with _output(output) as out:
        result = grep_log(logs[0], out, selection, first=first, final=final, errors=_errors(strict))
    _warn(logs[0], result.skipped, result.truncated)


@app.command()
def sort(
    log: Annotated[str, typer.Argument(metavar="LOG", help="An alog or session directory.")],
    window: Annotated[
        int,
        typer.Option("--window", metavar="N", help="Entries held back to put the log in order."),
    ] = DEFAULT_WINDOW,
    output: Output = None,
    strict: Strict = False,
) -> None:
    """Write a log in time order (alogsort, with a larger window); says how many were late."""
    source = open_log(log)
    with _output(output) as out:
        result = sort_log(source, out, window=window, errors=_errors(strict))
    _warn(source, result.skipped, result.truncated)
    if result.late:
        err_console().print(
            f"{result.late} entries were displaced by more than {window} entries and are"
            " still out of order; give a larger --window"
        )
        raise typer.Exit(1)


@app.command()
def merge(
    logs: Annotated[
        list[str], typer.Argument(metavar="LOG...", help="alogs or sessions, one per vehicle.")
    ],
    vehicles: Annotated[
        list[str] | None,
        typer.Option(
            "--as",
            metavar="VEHICLE",
            help="The vehicle of each log, in order (default: found"
            " from its MOOSDB's DB_TIME, else the file's name).",
        ),
    ] = None,
    keep_source: Annotated[
        bool,
        typer.Option(
            "--keep-source",
            help="Leave the source column as it is (default: append @VEHICLE, as pLogger marks"
            " other communities).",
        ),
    ] = False,
    window: Annotated[
        int, typer.Option("--window", metavar="N", help="Entries each log holds back to sort.")
    ] = DEFAULT_WINDOW,
    output: Output = None,
    strict: Strict = False,
) -> None:
    """Merge several vehicles' logs into one alog by absolute time, on the earliest LOGSTART."""
    names = list(vehicles or [])
    if names and len(names) != len(logs):
        msg = f"--as was given {len(names)} times for {len(logs)} logs: give it once per log"
        raise UsageError(msg)
    inputs = [open_log(spec, names[i] if names else None) for i, spec in enumerate(logs)]
    _merge(inputs, output, None, "none" if keep_source else "source", window, strict)


def _merge(
    logs: list[LogInput],
    output: Path | None,
    selection: Selection | None,
    mark: str,
    window: int,
    strict: bool,
) -> None:
    with _output(output) as out:
        result = merge_logs(
            logs,
            out,
            mark="none" if mark == "none" else "source",
            selection=selection,
            window=window,
            errors=_errors(strict),
            name=output.name if output is not None else "merged.alog",
        )
    for name in result.truncated:
        err_console().print(f"{name}: the log was cut (a crash, or still being written)")
    if result.skipped:
        err_console().print(f"{result.skipped} line(s) were neither entries nor comments")
    if result.late:
        err_console().print(
            f"{result.late} entries were displaced by more than {window} entries and are"
            " still out of order; give a larger --window"
        )
        raise typer.Exit(1)
