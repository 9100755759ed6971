"""The typer application and the error handling every command shares."""

from __future__ import annotations

import sys

import typer

from fleetlog import __version__
from fleetlog.errors import FleetlogError

__all__ = ["app", "main"]

app = typer.Typer(
    name="fleetlog",
    help="Record, serve and replay MOOS logs for fleets of vehicles over Eclipse Zenoh.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"fleetlog {__version__}")
        raise typer.Exit


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Record, serve and replay MOOS logs for fleets of vehicles over Eclipse Zenoh."""


def main() -> None:
    """Run the CLI; any FleetlogError becomes one sentence on stderr and exit status 1."""
    try:
        # Inside the guard: a Ctrl-C while the commands (and zenoh) load is a quiet exit too.
        from fleetlog.cli import commands  # noqa: F401  (registers the commands)

        app()
    except FleetlogError as err:
        print(f"fleetlog: error: {err}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)
