"""``fleetlog fleet``: the vehicles up now, each with its latest session."""

from __future__ import annotations

import json
import sys
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, Mode, NoScouting, Root
from fleetlog.cli.shore import open_client
from fleetlog.cli.tables import console, fleet_table
from fleetlog.errors import QueryError

__all__ = ["fleet"]


@app.command()
def fleet(
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object per vehicle instead of a table.")
    ] = False,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """List the vehicles up now (a recorder or a log server), each with its latest session."""
    with open_client(root, mode, connect, listen, config, no_multicast_scouting) as client:
        vehicles = client.vehicles()
        latest = client.latest_all() if vehicles else {}
        hint = client.nobody_hint() if not vehicles else ""
    if not vehicles:
        if hint:
            # Through a router, silence may be a refusal: an error, not an empty fleet.
            msg = f"no vehicle answered{hint}"
            raise QueryError(msg)
        print(
            "fleetlog: no vehicle is up (no recorder or serve token answered; check"
            " --connect / --mode)",
            file=sys.stderr,
        )
        return
    if as_json:
        for vehicle in sorted(vehicles):
            info = latest.get(vehicle)
            row = {
                "vehicle": vehicle,
                "up": sorted(vehicles[vehicle]),
                "latest": json.loads(info.to_json()) if info is not None else None,
            }
            print(json.dumps(row))
        return
    console().print(fleet_table(vehicles, latest))
