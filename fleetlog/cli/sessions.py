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
from fleetlog.cli.shore import open_client
from fleetlog.cli.tables import console, sessions_table

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
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """List a vehicle's log sessions, oldest first; the latest is marked with '*'."""
    checked_vehicle(vehicle, "VEHICLE")
    checked_seconds(timeout, "--timeout", zero=False)
    with open_client(root, mode, connect, listen, config, no_multicast_scouting) as client:
        client.require(vehicle)
        found = client.sessions(vehicle, timeout=timeout)
        latest = client.latest(vehicle).session
    if as_json:
        for info in found:
            print(json.dumps({**info.as_json(), "latest": info.name == latest}))
        return
    console().print(sessions_table(found, latest))
