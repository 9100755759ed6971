"""What the shore commands share: the fleet client, discovery options, and how they report.

Every shore command opens its client here (:func:`open_client`), waits for the fleet with
:func:`discover` (``--expect`` / ``--wait``), and says what it could not do through
:func:`warn` and :func:`finish`: the one place where shore-side failures become words.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from fleetlog.cli.options import checked_root, checked_seconds, checked_vehicle, session_options
from fleetlog.errors import FormatError, UsageError
from fleetlog.moos.units import parse_size
from fleetlog.shore.client import FleetClient
from fleetlog.shore.discovery import WAIT, FleetView
from fleetlog.shore.report import FleetReport

__all__ = [
    "WAIT",
    "Expect",
    "MinFreeDisk",
    "Wait",
    "checked_min_free",
    "discover",
    "finish",
    "open_client",
    "warn",
]

_DISCOVERY = "Discovery"

Expect = Annotated[
    list[str] | None,
    typer.Option(
        "--expect",
        metavar="VEHICLE",
        help="A vehicle that should be up (repeatable): proceed as soon as all are seen, and"
        " name those that are not.",
        rich_help_panel=_DISCOVERY,
    ),
]
Wait = Annotated[
    float,
    typer.Option(
        "--wait",
        metavar="SECONDS",
        help="Seconds to wait for the fleet at most. Without --expect the fleet is taken as"
        " known once no new vehicle or peer appeared for 0.3 s.",
        rich_help_panel=_DISCOVERY,
    ),
]


MinFreeDisk = Annotated[
    str,
    typer.Option(
        "--min-free-disk",
        metavar="SIZE",
        help="Leave SIZE free where the files go (e.g. 1GB; 0: no check): a file that would go"
        " below is not fetched, and what is fetched so far is kept.",
    ),
]


def checked_min_free(text: str) -> int:
    """Read ``--min-free-disk``.

    Raises:
        UsageError: not a size.
    """
    try:
        return parse_size(text, name="--min-free-disk")
    except FormatError as err:
        raise UsageError(str(err)) from None


def open_client(
    root: str,
    mode: str | None,
    connect: list[str] | None,
    listen: list[str] | None,
    config: Path | None,
    no_multicast_scouting: bool,
    *,
    timeout: float = 10.0,
    grep_timeout: float = 300.0,
    wait: float = WAIT,
) -> FleetClient:
    """Open a :class:`FleetClient` with the shared command-line options.

    Raises:
        UsageError: an option is unusable.
        TransportError: the Zenoh session cannot be opened.
    """
    key_root = checked_root(root)
    checked_seconds(wait, "--wait")
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    return FleetClient.open(
        zopts, root=key_root, timeout=timeout, grep_timeout=grep_timeout, wait=wait
    )


def checked_expect(expect: list[str] | None) -> tuple[str, ...]:
    """Validate ``--expect``.

    Raises:
        UsageError: an empty vehicle name.
    """
    return tuple(checked_vehicle(v, "--expect") for v in expect or ())


def discover(client: FleetClient, expect: list[str] | None, *, say: bool = True) -> FleetView:
    """Wait for the fleet; say on stderr who is up and who of ``expect`` is not.

    Raises:
        UsageError: an empty ``--expect`` name.
    """
    view = client.discover(checked_expect(expect))
    if say:
        print(f"fleetlog: {view.describe()}", file=sys.stderr)
    return view


def warn(text: str) -> None:
    """A note on stderr that does not stop the command."""
    print(f"fleetlog: warning: {text}", file=sys.stderr)


def finish(report: FleetReport) -> None:
    """End a command over several vehicles: non-zero, naming what was not done, if any.

    Raises:
        PartialError: a vehicle is missing or failed.
    """
    for vehicle, why in sorted(report.skipped.items()):
        warn(f"vehicle {vehicle}: {why}")
    report.check()
