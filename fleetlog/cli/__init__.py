"""The ``fleetlog`` command line: thin typer commands over the engines (``fleetlog.cli.app``)."""

from __future__ import annotations

import sys

__all__ = ["main"]


def main() -> None:
    """Run the CLI (``fleetlog`` and ``python -m fleetlog``).

    The commands' modules (typer, rich, zenoh) are imported here, inside the guard: a Ctrl-C
    while they load ends the command with status 130 and no traceback, as it does later.
    """
    try:
        from fleetlog.cli.app import main as run
    except KeyboardInterrupt:
        sys.exit(130)
    run()
