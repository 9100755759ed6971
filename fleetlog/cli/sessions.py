"""``fleetlog sessions V``: a vehicle's sessions."""

from __future__ import annotations

import json
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
from fleetlog.cli.shore import WAIT, Wait, open_client, warn
from fleetlog.cli.tables import clock_warning, console, sessions_table
from fleetlog.wire.query import LatestInfo

__all__ = ["sessions"]


@app.command()
def sessions(
    vehicle: Annotated[
        str,
        typer.Argument(
            metavar="VEHICLE", help="The vehicle (its MOOS community).", show_default=False
        ),
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object per session instead of a table.")
    ] = False,
    timeout: Annotated[
        float,
        typer.Option(
            "--timeout",
            metavar="SECONDS",
            help="Seconds to wait (a first listing reads every alog).",
        ),
    ] = 120.0,
    server: Annotated[
        str | None,
        typer.Option(
            "--server",
            metavar="ZID",
            help="List this process's sessions only (its Zenoh id), when two recorders answer"
            " for the vehicle.",
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
    """List a vehicle's log sessions, oldest first; the latest is marked with '*'.

    When two processes answer for the vehicle (two recorders after a partition healed),
    each one's sessions are listed under its Zenoh id.
    """
    checked_vehicle(vehicle, "VEHICLE")
    checked_seconds(timeout, "--timeout", zero=False)
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        client.require(vehicle)
        found = client.sessions_by_server(vehicle, timeout=timeout, server=server)
        latest: dict[str | None, LatestInfo] = {a.server: a for a in client.latest_answers(vehicle)}
    if len(found) > 1:
        warn(
            f"vehicle {vehicle}: {len(found)} processes answer ({', '.join(map(str, found))});"
            " two recorders of one vehicle (a partition that healed?)"
        )
    unsynced = [s.name for infos in found.values() for s in infos if s.synced is False]
    warning = clock_warning(vehicle, unsynced)
    if warning is not None:
        warn(warning)
    for zid, infos in found.items():
        info = latest.get(zid)
        newest = info.session if info is not None else None
        if as_json:
            for item in infos:
                row = {**item.as_json(), "latest": item.name == newest}
                if len(found) > 1:
                    row["server"] = zid
                print(json.dumps(row))
            continue
        if len(found) > 1:
            console().print(f"[bold]{vehicle}@{zid}[/bold]")
        console().print(sessions_table(infos, newest))
