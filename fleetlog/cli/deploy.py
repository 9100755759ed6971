"""``fleetlog deploy``: a fleet's certificates and configurations (init, renew, revoke, check)."""

from __future__ import annotations

import datetime as dt
import sys
from pathlib import Path
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, Mode, NoScouting, session_options
from fleetlog.cli.settings import settings
from fleetlog.deploy.check import fleet_findings, machine_findings
from fleetlog.deploy.fleet import DEFAULT_PORT, SHORE, Fleet, Machine, parse_address
from fleetlog.deploy.kit import FleetKit, parse_holder
from fleetlog.errors import FormatError, UsageError
from fleetlog.wire.keys import DEFAULT_ROOT

__all__ = ["deploy"]

deploy = typer.Typer(
    name="deploy",
    help="Make and keep a fleet's certificates and Zenoh configurations (the security profile).",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(deploy)

FleetDir = Annotated[
    Path,
    typer.Argument(metavar="FLEET_DIR", help="The fleet directory (fleet.json, ca/, machines)."),
]
Days = Annotated[
    int, typer.Option("--days", metavar="DAYS", help="How long new certificates are valid.")
]


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _days(days: int) -> int:
    if not 1 <= days <= 3650:
        msg = f"--days must be 1 to 3650, not {days}"
        raise UsageError(msg)
    return days


def _vehicle(spec: str) -> Machine:
    name, at, address = spec.partition("@")
    if not at:
        return Machine(name)
    host, port = parse_address(address, DEFAULT_PORT)
    return Machine(name, [host], port)


@deploy.command()
def init(
    directory: FleetDir,
    vehicle: Annotated[
        list[str],
        typer.Option(
            "--vehicle",
            metavar="NAME[@HOST[:PORT]]",
            help="A vehicle (repeatable); @HOST is where its router can be reached, if anywhere.",
        ),
    ],
    shore: Annotated[
        list[str],
        typer.Option(
            "--shore",
            metavar="HOST[:PORT]",
            help="The shore router's address as the vehicles dial it (repeatable: every name"
            " and address it has; the first is dialled).",
        ),
    ],
    operator: Annotated[
        list[str] | None,
        typer.Option("--operator", metavar="NAME", help="An operator (repeatable)."),
    ] = None,
    replay: Annotated[
        list[str] | None,
        typer.Option("--replay", metavar="NAME", help="A replay host (repeatable)."),
    ] = None,
    name: Annotated[
        str | None,
        typer.Option("--name", metavar="FLEET", help="The fleet's name [default: FLEET_DIR's]."),
    ] = None,
    root: Annotated[
        str | None,
        typer.Option(
            "--root", metavar="ROOT", help="Key root [default: the settings', else fleet]."
        ),
    ] = None,
    replay_prefix: Annotated[
        str,
        typer.Option(
            "--replay-prefix", metavar="PREFIX", help="Replay hosts publish as PREFIX<vehicle>."
        ),
    ] = "sim_",
    replay_into: Annotated[
        list[str] | None,
        typer.Option(
            "--replay-into",
            metavar="VEHICLE",
            help="A live vehicle replay hosts may publish into (repeatable).",
        ),
    ] = None,
    etc: Annotated[
        str,
        typer.Option(
            "--etc",
            metavar="DIR",
            help="Where each machine's files will be installed.",
        ),
    ] = "/etc/fleetlog",
    in_place: Annotated[
        bool,
        typer.Option(
            "--in-place",
            help="Configurations name the files where they are made (one machine: a trial,"
            " tests, the demo) instead of --etc.",
        ),
    ] = False,
    days: Days = 365,
) -> None:
    """Create a fleet: its CA, every certificate, and every machine's configuration.

    Writes FLEET_DIR/ca (keep ca.key off the vehicles), FLEET_DIR/shore,
    FLEET_DIR/vehicles/NAME, FLEET_DIR/operators/NAME and FLEET_DIR/replays/NAME: each machine
    directory is that machine's /etc/fleetlog. The shore also gets an operator identity of its
    own (shore tools, the collector).
    """
    shore_machine = Machine(SHORE)
    port = DEFAULT_PORT
    for i, text in enumerate(shore):
        host, p = parse_address(text, DEFAULT_PORT)
        shore_machine.addresses.append(host)
        if i == 0:
            port = p
    shore_machine.port = port
    if not shore_machine.addresses:
        msg = "--shore needs the shore router's address as the vehicles reach it"
        raise UsageError(msg)
    vehicles = [_vehicle(v) for v in vehicle]
    names = [v.name for v in vehicles]
    if len(set(names)) != len(names):
        msg = "a vehicle is named twice"
        raise UsageError(msg)
    fleet = Fleet(
        name=name or directory.resolve().name,
        root=root or settings().get("root") or DEFAULT_ROOT,
        shore=shore_machine,
        vehicles={v.name: v for v in vehicles},
        operators=sorted(set(operator or ["ops"])),
        replays=sorted(set(replay or ())),
        replay_prefix=replay_prefix,
        replay_into=sorted(set(replay_into or ())),
        etc="" if in_place else etc,
    )
    try:
        written = FleetKit(directory).init(fleet, _now(), _days(days))
    except FormatError as err:
        raise UsageError(str(err)) from None
    print(f"fleet {fleet.name!r}: {len(fleet.holders())} certificates, root {fleet.root!r}")
    for where in written:
        print(f"  {directory / where}/")
    print(
        f"Keep {directory / 'ca' / 'ca.key'} off the vehicles. Install each machine directory"
        f" as {etc} (docs/deploy.md)."
        if not in_place
        else "The configurations name the files where they are: run everything on this machine."
    )


@deploy.command()
def renew(
    directory: FleetDir,
    holder: Annotated[
        str, typer.Argument(metavar="ROLE:NAME", help="vehicle:alpha, router:shore, operator:ops…")
    ],
    days: Days = 365,
) -> None:
    """Issue a fresh certificate for one holder (same identity, new key and expiry)."""
    try:
        role, name = parse_holder(holder)
        done = FleetKit(directory).renew(role, name, _now(), _days(days))
    except FormatError as err:
        raise UsageError(str(err)) from None
    print("\n".join(done.lines()))


@deploy.command()
def revoke(
    directory: FleetDir,
    holder: Annotated[
        str, typer.Argument(metavar="ROLE:NAME", help="vehicle:bravo, operator:ops…")
    ],
    reason: Annotated[
        str, typer.Option("--reason", metavar="TEXT", help="Why, for the fleet's record.")
    ] = "",
    days: Days = 365,
) -> None:
    """Revoke a holder's certificate: every router stops granting it anything.

    Zenoh has no revocation list, so the revoked common name is removed from the access
    control of every router, and the holder gets a new identity (its name's next generation)
    with a new certificate. Prints what must be copied where: every router's router.json5,
    and the holder's new certificate.
    """
    try:
        role, name = parse_holder(holder)
        done = FleetKit(directory).revoke(role, name, _now(), _days(days), reason)
    except FormatError as err:
        raise UsageError(str(err)) from None
    print("\n".join(done.lines()))


@deploy.command()
def check(
    directory: Annotated[
        Path | None,
        typer.Argument(
            metavar="[FLEET_DIR]",
            help="A fleet directory to check every certificate of [default: this machine].",
            show_default=False,
        ),
    ] = None,
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Show this machine's configuration and identity, or a fleet's certificates, and expiry.

    Exits 1 when a certificate has expired or does not fit (errors), 0 otherwise; warnings
    (a certificate expiring within 30 days) are printed and exit 0.
    """
    if directory is not None:
        findings = fleet_findings(FleetKit(directory), _now())
    else:
        zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
        findings = machine_findings(zopts, _now())
        print(f"settings: {settings().describe()}")
    for finding in findings:
        print(finding)
    if any(f.level == "error" for f in findings):
        sys.exit(1)
