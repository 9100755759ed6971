"""``fleetlog fleet``: the vehicles up now, each with its latest session."""

from __future__ import annotations

import json
import sys
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, Mode, NoScouting, Root
from fleetlog.cli.shore import WAIT, Expect, Wait, discover, finish, open_client, warn
from fleetlog.cli.tables import console, fleet_table
from fleetlog.errors import QueryError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.report import FleetReport
from fleetlog.wire.query import LatestInfo
from fleetlog.wire.version import version_problem

__all__ = ["fleet"]


def latest_of_fleet(client: FleetClient, vehicles: list[str]) -> dict[str, list[LatestInfo]]:
    """Every vehicle's latest session, one answer per process that serves it.

    One query asks the whole fleet; a vehicle missing from its answers (one that just came
    up) is asked on its own. A vehicle that still does not answer is left out.
    """
    found = client.latest_all()
    for vehicle in vehicles:
        if vehicle not in found:
            try:
                found[vehicle] = client.latest_answers(vehicle)
            except QueryError:
                continue
    return found


def report_conflicts(latest: dict[str, list[LatestInfo]]) -> None:
    """Warn about each vehicle that two processes answer for."""
    for vehicle, answers in sorted(latest.items()):
        if len(answers) > 1:
            who = ", ".join(sorted(f"{a.server} ({_role(a)})" for a in answers))
            warn(
                f"vehicle {vehicle}: {len(answers)} processes answer: {who}; two recorders of"
                " one vehicle (a partition that healed?). fetch writes each one's sessions to"
                f" DIR/{vehicle}@ZID/"
            )


def _role(info: LatestInfo) -> str:
    return "recorder" if info.recorder is not None else "serve"


@app.command()
def fleet(
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object per vehicle instead of a table.")
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
    """List the vehicles up now (a recorder or a log server), each with its latest session.

    Waits until every --expect'ed vehicle is up, else until no new vehicle appeared for a
    moment (at most --wait seconds); exits non-zero naming the expected vehicles not up.
    """
    report = FleetReport("found")
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        view = discover(client, expect, say=False)
        report.missing = view.missing
        latest = latest_of_fleet(client, view.names) if view.vehicles else {}
        hint = client.nobody_hint() if not view.vehicles else ""
    print(f"fleetlog: {view.describe()}", file=sys.stderr)
    if not view.vehicles and hint:
        # Through a router, silence may be a refusal: an error, not an empty fleet.
        msg = f"no vehicle answered{hint}"
        raise QueryError(msg)
    if not view.vehicles and not view.missing:
        print(
            "fleetlog: no vehicle is up (no recorder or serve token answered; check"
            " --connect / --mode)",
            file=sys.stderr,
        )
        return
    for vehicle in view.names:
        report.done[vehicle] = "up"
    report_conflicts(latest)
    for vehicle, answers in sorted(latest.items()):
        for found in answers:
            problem = version_problem(vehicle, found.wire)
            if problem is not None:
                warn(problem)
    for vehicle in view.names:
        for info in latest.get(vehicle, []):
            if info is not None and info.synced is False and info.session is not None:
                print(
                    f"fleetlog: warning: {vehicle}'s clock was not synchronised when its"
                    f" latest session {info.session} opened: its absolute times may be off",
                    file=sys.stderr,
                )
    if as_json:
        for vehicle in view.names:
            answers = latest.get(vehicle, [])
            row = {
                "vehicle": vehicle,
                "up": sorted(view.vehicles[vehicle]),
                "latest": json.loads(answers[0].to_json()) if answers else None,
                "conflict": [a.server for a in answers] if len(answers) > 1 else None,
                "answers": [json.loads(a.to_json()) for a in answers],
            }
            print(json.dumps(row))
    elif view.vehicles:
        console().print(fleet_table(view.vehicles, latest))
    finish(report)
