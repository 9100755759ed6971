"""``fleetlog poke``: publish MOOS variables by hand, as uPokeDB does."""

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
    checked_root,
    checked_seconds,
    checked_vehicle,
    session_options,
)
from fleetlog.cli.settings import settings
from fleetlog.deploy.identity import publish_refusal, this_identity
from fleetlog.errors import QueryError, UsageError
from fleetlog.transport.services import refusal_hint
from fleetlog.wire.keys import service_key, var_key

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
            " reachable recorder's].",
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
            help="Seconds to wait for a subscriber and for the recorder's confirmation.",
        ),
    ] = 3.0,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Publish MOOS variables to a vehicle and wait until they were delivered.

    VAR=VALUE publishes a double when VALUE is a number (not nan/inf), else a string;
    VAR:=STRING always publishes a string. Exits non-zero if nobody subscribes.
    """
    parsed = [parse_assignment(a) for a in assignments]
    checked_seconds(wait, "--wait")
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    vehicle = vehicle or settings().get("vehicle")
    key_root = checked_root(root)
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    who = this_identity(zopts)
    with Vehicle(vehicle, source=source, options=zopts, root=key_root) as v:
        if who is not None:
            # The routers drop a refused put silently: refuse it here, where it can be said.
            for name, _ in parsed:
                refusal = publish_refusal(who, v.vehicle, name)
                if refusal is not None:
                    raise QueryError(refusal)
        for name, value in parsed:
            if not v.wait_for_subscriber(name, timeout=wait):
                msg = f"nobody subscribes to {name} of vehicle {v.vehicle!r}; nothing was delivered"
                raise QueryError(msg)
            v.publish(name, value)
            kind = "double" if isinstance(value, float) else "string"
            shown = repr(value)
            if len(shown) > _SHOWN:
                shown = f"{shown[: _SHOWN - 5]}...{shown[-1]} ({len(str(value))} characters)"
            print(f"{name} = {shown} ({kind}) -> vehicle {v.vehicle}", file=sys.stderr)
        if not v.confirm(timeout=wait):
            # No recorder answered; give plain subscribers a moment before the session closes.
            time.sleep(0.3)
            status = service_key(key_root, v.vehicle, "status")
            hint = refusal_hint(v.session, "put or the status query", status)
            if hint:
                keys = ", ".join(var_key(key_root, v.vehicle, name) for name, _ in parsed)
                msg = f"no recorder of vehicle {v.vehicle!r} confirmed the put on {keys}{hint}"
                raise QueryError(msg)
            print("fleetlog: warning: no recorder confirmed receipt", file=sys.stderr)
