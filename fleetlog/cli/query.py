"""``fleetlog query``: a remote aloggrep/alogclip over a vehicle's session."""

from __future__ import annotations

import csv
import datetime as dt
import json
import sys
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_seconds,
    checked_vehicle,
)
from fleetlog.cli.shore import WAIT, Wait, open_client
from fleetlog.errors import FormatError, QueryError, UsageError
from fleetlog.moos.alog import Variant, format_entry
from fleetlog.shore.answers import GrepStream
from fleetlog.wire.query import (
    DEFAULT_GREP_LIMIT,
    MAX_GREP_LIMIT,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    TimeBound,
    check_component,
    parse_grep_request,
)

__all__ = ["alog_line", "parse_time", "query"]

_FORMATS = ("alog", "csv", "json")
_KIND_NAMES = {"d": "double", "s": "string", "b": "binary"}


def parse_time(text: str, option: str) -> TimeBound:
    """Read ``--from``/``--to``: seconds since LOGSTART, ``@EPOCH``, or an ISO 8601 time.

    An ISO time without a zone is UTC (``2025-06-19T12:04:55``; ``+02:00`` or ``Z`` may
    follow).

    Raises:
        UsageError: none of the three.
    """
    try:
        return TimeBound.parse(text, option)
    except FormatError as err:
        if text.startswith("@"):
            raise UsageError(str(err)) from None
    try:
        when = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        msg = (
            f"{option} {text!r} is neither seconds since LOGSTART (12.5), seconds since the"
            " epoch (@1750334690.5) nor an ISO 8601 time (2025-06-19T12:04:55Z)"
        )
        raise UsageError(msg) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=dt.UTC)
    return TimeBound(when.timestamp(), absolute=True)


def alog_line(header: GrepHeader, record: GrepRecord) -> str:
    """Return a record as the alog line(s) pLogger wrote for it (same time decimals)."""
    text = record.text
    if record.kind == "d":
        text = text.ljust(12)
        if header.mark_data_type:
            text = "D:" + text
    elif record.kind == "s" and header.mark_data_type:
        text = "S:" + text
    variant = Variant.EM if header.time_decimals == 3 else Variant.IVP
    return format_entry(
        record.offset, record.key, record.source, text, variant=variant, binary=record.kind == "b"
    )


@app.command()
def query(
    vehicle: Annotated[
        str,
        typer.Argument(
            metavar="VEHICLE", help="The vehicle (its MOOS community).", show_default=False
        ),
    ],
    variables: Annotated[
        list[str] | None,
        typer.Argument(
            metavar="VAR",
            show_default=False,
            help="Variables to keep (MOOS globs: NAV_*, DB_?IME) [default: all].",
        ),
    ] = None,
    session: Annotated[
        str | None,
        typer.Option(
            "--session", "-s", metavar="SESSION", help="The session [default: the latest]."
        ),
    ] = None,
    source: Annotated[
        list[str] | None,
        typer.Option(
            "--source",
            metavar="GLOB",
            help="Sources to keep (MOOS globs, on the source or its process name; repeatable).",
        ),
    ] = None,
    start: Annotated[
        str | None,
        typer.Option(
            "--from",
            metavar="TIME",
            help="Start: seconds since LOGSTART, @EPOCH, or an ISO 8601 time (UTC by default).",
        ),
    ] = None,
    end: Annotated[
        str | None, typer.Option("--to", metavar="TIME", help="End, as --from (inclusive).")
    ] = None,
    limit: Annotated[
        int,
        typer.Option(
            "--limit", metavar="N", help=f"At most this many entries (up to {MAX_GREP_LIMIT})."
        ),
    ] = DEFAULT_GREP_LIMIT,
    fmt: Annotated[
        str, typer.Option("--format", metavar="FORMAT", help="alog, csv or json (one per line).")
    ] = "alog",
    timeout: Annotated[
        float,
        typer.Option("--timeout", metavar="SECONDS", help="Seconds the whole answer may take."),
    ] = 300.0,
    server: Annotated[
        str | None,
        typer.Option(
            "--server",
            metavar="ZID",
            help="Ask this process only (its Zenoh id), when two recorders answer for the vehicle.",
        ),
    ] = None,
    wait: Wait = WAIT,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Print the entries of a vehicle's session that match, without downloading the log.

    A remote aloggrep/alogclip: entries whose variable matches a VAR, whose source matches a
    --source, and whose time lies in [--from, --to], in file order, up to --limit.
    """
    if fmt not in _FORMATS:
        msg = f"--format must be one of {', '.join(_FORMATS)}, not {fmt!r}"
        raise UsageError(msg)
    if not 1 <= limit <= MAX_GREP_LIMIT:
        msg = f"--limit must be between 1 and {MAX_GREP_LIMIT}, not {limit}"
        raise UsageError(msg)
    checked_vehicle(vehicle, "VEHICLE")
    checked_seconds(timeout, "--timeout", zero=False)
    first = parse_time(start, "--from") if start else None
    last = parse_time(end, "--to") if end else None
    if (
        first is not None
        and last is not None
        and first.absolute == last.absolute
        and first.value > last.value
    ):
        msg = f"--from {start} is after --to {end}: nothing can match"
        raise UsageError(msg)
    request = GrepRequest(tuple(variables or ()), tuple(source or ()), first, last, limit)
    try:
        if session is not None:
            check_component(session, "session")
        # The protocol's own parser: what the vehicle would refuse is refused here first.
        request = parse_grep_request(request.parameters())
    except FormatError as err:
        raise UsageError(str(err)) from None
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, grep_timeout=timeout, wait=wait
    ) as client:
        client.require(vehicle)
        # One process's answer: two recorders of one vehicle would interleave their greps.
        latest = client.latest(vehicle, server=server)
        if session is None:
            session = latest.session
            if session is None:
                msg = f"vehicle {vehicle} has no session"
                raise QueryError(msg)
        stream = client.grep(vehicle, session, request, server=server)
        _print(stream, fmt)
        end_record = stream.end
    if end_record is None:
        return
    if end_record.truncated:
        print(f"fleetlog: warning: stopped after {limit} entries (--limit)", file=sys.stderr)
    if end_record.skipped:
        # Otherwise a log the vehicle cannot read looks like one where nothing matched.
        print(
            f"fleetlog: warning: {end_record.skipped} line(s) of {session}'s alog are not alog"
            " entries and were skipped",
            file=sys.stderr,
        )
    if end_record.cut:
        print(
            f"fleetlog: warning: {session}'s alog ends inside an entry (still being written,"
            " or cut short); that entry is left out",
            file=sys.stderr,
        )


def _print(stream: GrepStream, fmt: str) -> None:
    out = sys.stdout
    writer = csv.writer(out) if fmt == "csv" else None
    started = False
    for record in stream:
        header = stream.header
        if header is None:  # pragma: no cover - the vehicle always sends it first
            msg = "the grep answer has no header"
            raise QueryError(msg)
        if not started:
            started = True
            if fmt == "alog":
                out.write("".join(line + "\n" for line in header.banner))
            elif writer is not None:
                writer.writerow(["time", "abs_time", "var", "source", "type", "value"])
        absolute = None if header.logstart is None else header.logstart + record.offset
        if fmt == "alog":
            out.write(alog_line(header, record))
        elif writer is not None:
            writer.writerow(
                [
                    repr(record.offset),
                    "" if absolute is None else f"{absolute:.6f}",
                    record.key,
                    record.source,
                    _KIND_NAMES[record.kind],
                    record.text,
                ]
            )
        else:
            value: object = float(record.text) if record.kind == "d" else record.text
            obj = {
                "time": record.offset,
                "abs_time": absolute,
                "var": record.key,
                "source": record.source,
                "type": _KIND_NAMES[record.kind],
                "value": value,
                "line": record.lineno,
            }
            out.write(json.dumps(obj) + "\n")
    if not started and fmt == "alog" and stream.header is not None:
        out.write("".join(line + "\n" for line in stream.header.banner))
    out.flush()
