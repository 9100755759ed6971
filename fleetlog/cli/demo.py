"""``fleetlog demo``: a secured fleet on this machine, recorded, fetched, grepped, replayed."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import checked_seconds

__all__ = ["demo"]


@app.command()
def demo(
    directory: Annotated[
        Path,
        typer.Argument(metavar="DIR", help="Where the demo's fleet, logs and copies go."),
    ] = Path("fleetlog-demo"),
    seconds: Annotated[
        float, typer.Option("--seconds", metavar="S", help="How long the vehicles record.")
    ] = 15.0,
    no_netns: Annotated[
        bool,
        typer.Option(
            "--no-netns",
            help="Everything on loopback, even where network namespaces and radios can be made.",
        ),
    ] = False,
) -> None:
    """Run a whole fleet here: routers, three vehicles and a shore, security profile on.

    It makes a fleet (deploy init), starts the shore's and each vehicle's router, each
    vehicle's recorder with its own mission and its apps, then: lists the fleet, closes and
    fetches every vehicle's session, greps each remotely, shows a refusal of the access
    control, and replays the fleet together under the replay prefix. Run as root, each
    vehicle sits in a network namespace of its own behind a radio with delay, loss and a
    bandwidth cap. Every step is printed as the fleetlog command it runs.
    """
    from fleetlog.deploy.demo import run_demo

    checked_seconds(seconds, "--seconds", zero=False)
    run_demo(directory.resolve(), seconds, False if no_netns else None)
