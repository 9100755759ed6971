"""``fleetlog poke``: publish MOOS variables by hand, as uPokeDB does, and say what came of it."""

from __future__ import annotations

import math
import sys
import time
from typing import Annotated

import typer

from fleetlog.api import Vehicle
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
    session_options,
)
from fleetlog.cli.settings import settings
from fleetlog.cli.shore import open_client, warn
from fleetlog.deploy.identity import publish_refusal, this_identity
from fleetlog.errors import FleetlogError, QueryError, UsageError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.outcome import Sent, await_outcomes
from fleetlog.shore.status import describe_command
from fleetlog.transport.services import refusal_hint
from fleetlog.wire.keys import service_key, var_key
from fleetlog.wire.query import RECORDER_TOKEN

__all__ = ["parse_assignment", "poke"]

#: how much of a value the confirmation line shows
_SHOWN = 80


def parse_assignment(text: str) -> tuple[str, float | str]:
    """Parse ``VAR=VALUE`` or ``VAR:=STRING`` with uPokeDB's rule.

    A VALUE that Python's ``float()`` accepts, other than nan and inf, is a double; any other
    VALUE, and anything after ``:=``, is a string.

    Raises:
        UsageError: no ``=``, or an empty or blank-containing variable name.
    """
    name, sep, value = text.partition("=")
    if not sep:
        msg = f"{text!r} is not VAR=VALUE or VAR:=STRING"
        raise UsageError(msg)
    forced = name.endswith(":")
    if forced:
        name = name[:-1]
    name = name.strip()
    if not name or any(c.isspace() for c in name):
        msg = f"{text!r}: the variable name must be non-empty and without blanks"
        raise UsageError(msg)
    if forced:
        return name, value
    try:
        number = float(value)
    except ValueError:
        return name, value
    if math.isnan(number) or math.isinf(number):
        return name, value
    return name, number


def _target(client: FleetClient, vehicle: str | None) -> str:
    """The vehicle to publish to: the one named, or the one recorder up.

    Found as the shore finds vehicles: a recorder whose token arrives a moment late is seen.
    """
    if vehicle is not None:
        client.discover(expect=(vehicle,))  # proceeds as soon as its recorder is seen
        return vehicle
    view = client.discover()
    recorders = [v for v in view.names if RECORDER_TOKEN in view.vehicles[v]]
    if not recorders:
        msg = "no fleetlog recorder is reachable; name the vehicle with --vehicle"
        raise QueryError(msg)
    if len(recorders) > 1:
        msg = f"several recorders are reachable ({', '.join(recorders)}); choose one with --vehicle"
        raise QueryError(msg)
    return recorders[0]


@app.command()
def poke(
    assignments: Annotated[
        list[str],
        typer.Argument(
            metavar="VAR=VALUE|VAR:=STRING", help="Variables to publish.", show_default=False
        ),
    ],
    vehicle: Annotated[
        str | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="NAME",
            help="Vehicle to publish to [default: this machine's (settings), else the one"
            " recorder up].",
        ),
    ] = None,
    source: Annotated[
        str, typer.Option("--source", metavar="NAME", help="Source process name to publish as.")
    ] = "uPokeDB",
    wait: Annotated[
        float,
        typer.Option(
            "--wait",
            metavar="SECONDS",
            help="Seconds to wait for the vehicle, for a subscriber, and for the recorder to"
            " confirm (and to say what it did with a command).",
        ),
    ] = 3.0,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Publish MOOS variables to a vehicle and wait until its recorder has them.

    VAR=VALUE publishes a double when VALUE is a number (not nan/inf), else a string;
    VAR:=STRING always publishes a string. For a command (LOGGER_RESTART, PLOGGER_CMD) it
    prints what the recorder did: the new session directory, or the refusal and why. Exits
    non-zero if nobody subscribes, if no recorder confirms receipt, or if the recorder
    refused a command.
    """
    parsed = [parse_assignment(a) for a in assignments]
    checked_seconds(wait, "--wait")
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    vehicle = vehicle or settings().get("vehicle")
    who = this_identity(session_options(mode, connect, listen, config, no_multicast_scouting))
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        target = _target(client, vehicle)
        if who is not None:
            # The routers drop a refused put silently: refuse it here, where it can be said.
            for name, _ in parsed:
                refusal = publish_refusal(who, target, name)
                if refusal is not None:
                    raise QueryError(refusal)
        sent: list[Sent] = []
        with Vehicle(target, source=source, session=client.zenoh, root=client.root) as v:
            for name, value in parsed:
                if not v.wait_for_subscriber(name, timeout=wait):
                    msg = (
                        f"nobody subscribes to {name} of vehicle {target!r}; nothing was delivered"
                    )
                    raise QueryError(msg)
                stamp = time.time()
                v.publish(name, value, time=stamp)
                sent.append(Sent(name, stamp))
                kind = "double" if isinstance(value, float) else "string"
                shown = repr(value)
                if len(shown) > _SHOWN:
                    shown = f"{shown[: _SHOWN - 5]}...{shown[-1]} ({len(str(value))} characters)"
                print(f"{name} = {shown} ({kind}) -> vehicle {target}", file=sys.stderr)
            delivery = await_outcomes(client, target, sent, source, wait)
            status = service_key(client.root, target, "status")
            hint = refusal_hint(client.zenoh, "put or the status query", status)
    if not delivery.confirmed:
        if hint:
            keys = ", ".join(var_key(client.root, target, name) for name, _ in parsed)
            msg = f"no recorder of vehicle {target!r} confirmed the put on {keys}{hint}"
            raise QueryError(msg)
        msg = (
            f"no recorder of vehicle {target!r} confirmed receipt within {wait:g} s"
            " (the variables went to whoever subscribes; nothing records them?)"
        )
        raise QueryError(msg)
    refused: list[str] = []
    for item, record in delivery.outcomes.items():
        if record is None:
            warn(f"the recorder has {item.name} but did not say what it did with it")
            continue
        print(f"recorder of {target}: {describe_command(record)}")
        if not record.ok:
            refused.append(f"the recorder refused {item.name}: {record.why}")
    if refused:
        raise FleetlogError("; ".join(refused))
