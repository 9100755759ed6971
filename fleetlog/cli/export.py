"""``fleetlog export`` and ``fleetlog plot``: logs for analysts (engines in fleetlog.export)."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.tables import err_console
from fleetlog.errors import FormatError, UsageError
from fleetlog.export import (
    Resolved,
    Select,
    Source,
    Tally,
    export_dataset,
    export_mcap,
    plot_format,
    plot_logs,
    resolve,
    write_csv_rows,
    write_csv_table,
    write_parquet,
)
from fleetlog.storage.columnar import Errors
from fleetlog.storage.outputs import atomic_output
from fleetlog.storage.select import Selection
from fleetlog.wire.query import TimeBound

__all__ = ["export", "plot"]

_FORMATS = {".parquet": "parquet", ".pq": "parquet", ".mcap": "mcap", ".csv": "csv"}

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
    typer.Option("--from", metavar="T", help="Start: seconds since each LOGSTART, or @EPOCH."),
]
To = Annotated[
    str | None,
    typer.Option("--to", metavar="T", help="End: seconds since each LOGSTART, or @EPOCH."),
]
Strict = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Fail on lines that are neither entries nor comments (default: count and go on).",
    ),
]


def _format(output: Path, given: str | None) -> str:
    if given is not None:
        kind = given.lower()
        if kind not in ("parquet", "mcap", "csv", "dataset"):
            msg = f"--format must be parquet, mcap, csv or dataset, not {given!r}"
            raise UsageError(msg)
        return kind
    if output.is_dir() or str(output).endswith(os.sep) or not output.suffix:
        return "dataset"
    found = _FORMATS.get(output.suffix.lower())
    if found is None:
        msg = (
            f"cannot tell the format of {output}: name it .parquet, .mcap or .csv, end it with"
            " / for a dataset, or give --format"
        )
        raise UsageError(msg)
    return found


def _selection(
    variables: list[str] | None, sources: list[str] | None, start: str | None, end: str | None
) -> Select:
    if not variables and not sources and start is None and end is None:
        return None
    low = None if start is None else TimeBound.parse(start, "--from")
    high = None if end is None else TimeBound.parse(end, "--to")

    def select(source: Source) -> Selection:
        try:
            return Selection.of(variables or (), sources or (), low, high, source.logstart)
        except FormatError as err:
            msg = f"{source.path}: {err}"
            raise UsageError(msg) from None

    return select


def _say(text: str) -> None:
    # soft_wrap: a path or a sentence stays on one line whatever the terminal's width
    err_console().print(text, soft_wrap=True, highlight=False, markup=False)


def _report(tally: Tally) -> None:
    for line in tally.warnings():
        _say(f"fleetlog: warning: {line}")


def _size(path: Path) -> str:
    try:
        size = path.stat().st_size
    except OSError:
        return "?"
    return f"{size / 1e6:,.1f} MB"


@app.command()
def export(
    sources_in: Annotated[
        list[str],
        typer.Argument(
            metavar="SOURCE...",
            help="alogs, sessions, a vehicle's sessions or a shore archive (ARCHIVE/VEHICLE/"
            "SESSION/, as fetch --all writes it).",
        ),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            metavar="OUT",
            help="OUT.parquet, OUT.mcap, OUT.csv, or DATASET/ (a directory: a fleet dataset).",
        ),
    ],
    fmt: Annotated[
        str | None,
        typer.Option(
            "--format", metavar="FORMAT", help="parquet, mcap, csv or dataset [default: from OUT]."
        ),
    ] = None,
    variables: Variables = None,
    sources: Sources = None,
    start: From = None,
    end: To = None,
    table: Annotated[
        bool,
        typer.Option("--table", help="CSV: a row per period, a column per variable (as the slog)."),
    ] = False,
    period: Annotated[
        float, typer.Option("--period", metavar="S", help="CSV --table: seconds per row.")
    ] = 1.0,
    hold: Annotated[
        bool,
        typer.Option("--hold", help="CSV --table: repeat a value until the next (default: blank)."),
    ] = False,
    epoch: Annotated[
        bool,
        typer.Option("--epoch", help="CSV --table: absolute times (default: since LOGSTART)."),
    ] = False,
    no_positions: Annotated[
        bool,
        typer.Option(
            "--no-positions",
            help="MCAP: no foxglove.LocationFix/PoseInFrame channels from NAV_* variables.",
        ),
    ] = False,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite OUT if it exists (not for a dataset).")
    ] = False,
    strict: Strict = False,
) -> None:
    """Export logs to Parquet, MCAP (Foxglove), CSV, or a fleet dataset of Parquet.

    \b
    fleetlog export SESSION -o mission.parquet      one row per entry
    fleetlog export SESSION -o mission.mcap         Foxglove opens it as it is
    fleetlog export SESSION -v NAV_X -o navx.csv    one variable
    fleetlog export SESSION --table -o sync.csv     a row per second, a column per variable
    fleetlog export ARCHIVE -o DATASET/             adds the sessions not exported yet
    """  # noqa: D301 - click's \b (keep the lines as they are) must be the real character
    kind = _format(output, fmt)
    errors: Errors = "raise" if strict else "skip"
    if kind == "dataset":
        if variables or sources or start or end:
            msg = "a dataset holds whole sessions: --var, --source, --from and --to do not apply"
            raise UsageError(msg)
        _dataset(resolve(list(sources_in)), output, errors)
        return
    if kind != "csv" and (table or hold or epoch):
        msg = "--table, --hold and --epoch are for CSV output"
        raise UsageError(msg)
    if table and not (math.isfinite(period) and period > 0):
        msg = f"--period must be a positive number of seconds, not {period:g}"
        raise UsageError(msg)
    if output.is_dir():
        msg = f"{output} is a directory; name a file, or give --format dataset"
        raise UsageError(msg)
    if output.exists() and not force:
        msg = f"{output} exists; give --force to overwrite it"
        raise UsageError(msg)
    resolved = resolve(list(sources_in))
    _pending(resolved)
    select = _selection(variables, sources, start, end)
    tally = Tally()
    began = time.monotonic()
    untimed = 0
    with atomic_output(output, overwrite=force) as out:
        if kind == "parquet":
            write_parquet(resolved.sources, out, tally, errors=errors, selection=select)
        elif kind == "csv" and table:
            write_csv_table(
                resolved.sources,
                out,
                tally,
                period=period,
                hold=hold,
                epoch=epoch,
                errors=errors,
                selection=select,
            )
        elif kind == "csv":
            write_csv_rows(resolved.sources, out, tally, errors=errors, selection=select)
        else:
            result = export_mcap(
                resolved.sources,
                out,
                tally,
                errors=errors,
                selection=select,
                positions=not no_positions,
            )
            untimed = result.untimed
    _report(tally)
    _say(
        f"exported {tally.entries:,} entries of {len(resolved.sources)} log(s) to {output}"
        f" ({_size(output)}, {time.monotonic() - began:.1f} s)"
    )
    if untimed:
        _say(
            f"fleetlog: {untimed:,} entries have no absolute time (no usable banner, or before"
            " 1970) and are not in the MCAP file"
        )
    if untimed or resolved.pending:
        raise typer.Exit(1)


def _pending(resolved: Resolved) -> None:
    for path in resolved.pending:
        _say(f"fleetlog: warning: {path}: its alog is still being fetched (.part); not exported")


def _dataset(resolved: Resolved, output: Path, errors: Errors) -> None:
    began = time.monotonic()

    def starting(vehicle: str, session: str) -> None:
        _say(f"{vehicle}/{session} ...")

    result = export_dataset(resolved, output, errors=errors, on_session=starting)
    _report(result.tally)
    _pending(resolved)
    for vehicle, session in result.changed:
        _say(
            f"fleetlog: warning: {vehicle}/{session} changed since it was exported; it is not"
            f" rewritten (remove its directory from {output} to export it again)"
        )
    _say(
        f"dataset {output}: {len(result.written)} session(s) added"
        f" ({sum(n for _, _, n in result.written):,} entries), {len(result.kept)} already"
        f" there, in {time.monotonic() - began:.1f} s"
    )
    if result.pending or result.changed:
        raise typer.Exit(1)


def _split_args(args: list[str]) -> tuple[list[str], list[str]]:
    logs = [a for a in args if os.path.exists(a)]
    names = [a for a in args if not os.path.exists(a)]
    return logs, names


@app.command()
def plot(
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="SOURCE... [VAR...]",
            help="alogs, sessions, vehicles' sessions or an archive, then the variables to"
            " plot over time (each vehicle a line).",
        ),
    ],
    output: Annotated[
        Path,
        typer.Option("-o", "--output", metavar="OUT", help="The image: .png, .svg or .pdf."),
    ],
    xy: Annotated[
        str | None,
        typer.Option("--xy", metavar="X,Y", help="A track: Y against X (e.g. NAV_X,NAV_Y)."),
    ] = None,
    title: Annotated[str | None, typer.Option("--title", help="A title above the plot.")] = None,
    size: Annotated[
        str | None,
        typer.Option("--size", metavar="WxH", help="The figure's size in inches (e.g. 9x6)."),
    ] = None,
    dpi: Annotated[int, typer.Option("--dpi", help="Dots per inch (PNG).")] = 100,
    strict: Strict = False,
) -> None:
    """Plot variables over time, or a track, for one vehicle or several overlaid.

    Needs matplotlib: pip install 'fleetlog[plot]'.
    """
    specs, names = _split_args(args)
    if not specs:
        msg = f"no such alog, session or archive among {', '.join(args)}"
        raise UsageError(msg)
    pair = None
    if xy is not None:
        parts = [p.strip() for p in xy.split(",")]
        if len(parts) != 2 or not all(parts):
            msg = f"--xy takes two variables, X,Y (e.g. NAV_X,NAV_Y), not {xy!r}"
            raise UsageError(msg)
        pair = (parts[0], parts[1])
        if names:
            msg = f"--xy draws a track; no other variables ({', '.join(names)}) go with it"
            raise UsageError(msg)
    figsize = None
    if size is not None:
        try:
            width, height = (float(v) for v in size.lower().split("x"))
        except ValueError:
            msg = f"--size is WIDTHxHEIGHT in inches (e.g. 9x6), not {size!r}"
            raise UsageError(msg) from None
        if not (0 < width <= 100 and 0 < height <= 100):
            msg = f"--size must be between 0 and 100 inches each way, not {size!r}"
            raise UsageError(msg)
        figsize = (width, height)
    if not 10 <= dpi <= 1200:
        msg = f"--dpi must be between 10 and 1200, not {dpi}"
        raise UsageError(msg)
    image_format = plot_format(output.name)
    resolved = resolve(specs)
    _pending(resolved)
    tally = Tally()
    with atomic_output(output) as out:
        result = plot_logs(
            resolved.sources,
            out,
            tally,
            variables=names,
            xy=pair,
            image_format=image_format,
            size=figsize,
            dpi=dpi,
            title=title,
            errors="raise" if strict else "skip",
        )
    _report(tally)
    for name in result.missing:
        _say(f"fleetlog: warning: {name} has no double values; not plotted")
    _say(f"plotted {sum(result.points.values()):,} points to {output}")
    if result.missing:
        raise typer.Exit(1)
