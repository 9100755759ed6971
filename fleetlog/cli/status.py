"""``fleetlog status [V]``: what a recorder (or every recorder of the fleet) is doing."""

from __future__ import annotations

import datetime as dt
import json
import sys
from typing import Annotated

import typer
from rich.table import Table

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_vehicle,
    session_options,
)
from fleetlog.cli.shore import WAIT, Expect, Wait, discover, finish, open_client, warn
from fleetlog.cli.tables import console, human_size, plain
from fleetlog.deploy.check import machine_findings
from fleetlog.errors import FleetlogError, QueryError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.report import FleetReport
from fleetlog.shore.status import COUNTERS, VehicleStatus, describe_command
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.query import RECORDER_TOKEN

__all__ = ["status"]

#: how many of the recorder's last commands the one-vehicle view shows
_SHOWN_COMMANDS = 8


def _clock(found: VehicleStatus) -> str:
    synced = found.clock_synchronized
    if synced is None:
        return "unknown"
    return "synchronized" if synced else "NOT synchronized"


def _disk(found: VehicleStatus) -> str:
    if found.disk_free is None:
        return "-"
    if found.disk_total:
        share = 100.0 * found.disk_free / found.disk_total
        return f"{human_size(found.disk_free)} ({share:.0f} %)"
    return human_size(found.disk_free)


def _when(epoch: float | None) -> str:
    if epoch is None:
        return "--:--:--"
    try:
        return dt.datetime.fromtimestamp(epoch, dt.UTC).strftime("%H:%M:%S")
    except (OverflowError, OSError, ValueError):
        return "--:--:--"


def _detail(found: VehicleStatus, conflict: bool) -> None:
    out = console()
    title = f"{found.vehicle}" + (f"  (recorder {found.server})" if conflict else "")
    out.print(plain(title, style="bold"))
    c = found.counters
    rows = [
        ("state", found.state),
        ("session", found.session or "-"),
        ("directory", found.directory or "-"),
        ("counters", ", ".join(f"{n} {c[n]}" for n in (*COUNTERS[:5], "paused_samples") if n in c)),
        ("losses", ", ".join(f"{n} {c[n]}" for n in COUNTERS[5:11] if n in c)),
        ("disk free", _disk(found)),
        ("clock", _clock(found)),
        ("last error", found.last_error or "-"),
    ]
    table = Table(box=None, pad_edge=False, show_header=False)
    table.add_column(no_wrap=True)
    table.add_column()
    for name, value in rows:
        table.add_row(name, plain(value))
    out.print(table)
    if found.commands:
        out.print(plain(f"last {min(len(found.commands), _SHOWN_COMMANDS)} command(s):"))
        for item in found.commands[-_SHOWN_COMMANDS:]:
            who = f" from {item.source}" if item.source else ""
            out.print(plain(f"  {_when(item.time)} {item.via}{who}: {describe_command(item)}"))


def _fleet_table(found: dict[str, list[VehicleStatus]], serve_only: list[str]) -> Table:
    conflict = any(len(items) > 1 for items in found.values())
    table = Table(box=None, pad_edge=False)
    columns = ["VEHICLE", "STATE", "SESSION", "LOGGED", "LOST", "SKEWED", "GARBLED", "WRITE ERR"]
    columns += ["DISK FREE", "CLOCK", "LAST ERROR"]
    for column in [*columns, "RECORDER"] if conflict else columns:
        table.add_column(column, no_wrap=column != "LAST ERROR")
    for vehicle in sorted({*found, *serve_only}):
        items = found.get(vehicle)
        if not items:
            row = [vehicle, "no recorder (fleetlog serve only)"]
            row += ["-"] * (len(columns) - len(row))
            table.add_row(*(plain(v) for v in row), *([""] if conflict else []))
            continue
        for item in items:
            c = item.counters
            row = [
                vehicle,
                item.state,
                item.session or "-",
                *(str(c.get(n, "-")) for n in ("logged", "lost", "skewed", "garbled")),
                str(c.get("write_errors", "-")),
                _disk(item),
                _clock(item),
                item.last_error or "-",
            ]
            if conflict:
                row.append(f"{item.server} (CONFLICT)" if len(items) > 1 else "")
            table.add_row(*(plain(v) for v in row))
    return table


def _row(found: VehicleStatus, conflict: bool) -> str:
    return json.dumps(
        {**found.raw, "vehicle": found.vehicle, "server": found.server, "conflict": conflict}
    )


def _one(client: FleetClient, vehicle: str, as_json: bool) -> None:
    view = client.require(vehicle)
    if RECORDER_TOKEN not in view.vehicles.get(vehicle, ()):
        msg = (
            f"vehicle {vehicle} runs no recorder (its logs are served by fleetlog serve);"
            " nothing records it now"
        )
        raise QueryError(msg)
    found = client.status(vehicle)
    conflict = len(found) > 1
    if conflict:
        servers = ", ".join(str(f.server) for f in found)
        warn(f"vehicle {vehicle}: {len(found)} recorders answer ({servers}): a partition healed?")
    for item in found:
        if as_json:
            print(_row(item, conflict))
        else:
            _detail(item, conflict)


def _fleet(client: FleetClient, expect: list[str] | None, as_json: bool) -> None:
    report = FleetReport("heard from")
    view = discover(client, expect)
    report.missing = view.missing
    found = client.status_all() if view.vehicles else {}
    serve_only: list[str] = []
    for vehicle in view.names:
        if RECORDER_TOKEN not in view.vehicles[vehicle]:
            serve_only.append(vehicle)
            report.skipped[vehicle] = "runs no recorder (served by fleetlog serve)"
            continue
        if vehicle not in found:
            try:
                found[vehicle] = client.status(vehicle)
            except QueryError as err:
                report.failed[vehicle] = str(err)
                continue
        report.done[vehicle] = "status"
        if len(found[vehicle]) > 1:
            servers = ", ".join(str(f.server) for f in found[vehicle])
            warn(f"vehicle {vehicle}: {len(found[vehicle])} recorders answer ({servers})")
    shown = {v: items for v, items in found.items() if v in view.vehicles}
    if as_json:
        for vehicle in sorted(shown):
            for item in shown[vehicle]:
                print(_row(item, len(shown[vehicle]) > 1))
    elif shown or serve_only:
        console().print(_fleet_table(shown, serve_only))
    elif not view.vehicles and not view.missing:
        print("fleetlog: no vehicle is up (check --connect / --mode)", file=sys.stderr)
    finish(report)


@app.command()
def status(
    vehicle: Annotated[
        str | None,
        typer.Argument(
            metavar="VEHICLE",
            help="One vehicle [default: every vehicle up, as a table].",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object per recorder.")
    ] = False,
    expect: Expect = None,
    wait: Wait = WAIT,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Show what a recorder is doing: its session, counters and losses, disk, clock, commands.

    Without VEHICLE, every recorder of the fleet as a table; exits non-zero naming the
    --expect'ed vehicles that are not up and the recorders that did not answer.
    """
    if vehicle is not None:
        checked_vehicle(vehicle, "VEHICLE")
    _this_machine(session_options(mode, connect, listen, config, no_multicast_scouting))
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        if vehicle is not None:
            _one(client, vehicle, as_json)
        else:
            _fleet(client, expect, as_json)


def _this_machine(options: SessionOptions) -> None:
    """This machine's configuration and certificate, on stderr: expiry shows long before."""
    try:
        findings = machine_findings(options, dt.datetime.now(dt.UTC))
    except FleetlogError as err:
        warn(f"this machine's configuration: {err}")
        return
    for finding in findings:
        if finding.text.startswith(("mode ", "listening on")):
            continue
        if finding.level == "ok":
            print(f"fleetlog: this machine: {finding.text}", file=sys.stderr)
        else:
            warn(f"this machine: {finding.text}")
