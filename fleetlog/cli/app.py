"""The typer application and the error handling every command shares."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from fleetlog import __version__
from fleetlog.cli import settings as global_settings
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
    settings: Annotated[
        Path | None,
        typer.Option(
            "--settings",
            metavar="FILE",
            help="fleetlog's settings file [default: $FLEETLOG_SETTINGS, else"
            " /etc/fleetlog/fleetlog.toml if present].",
        ),
    ] = None,
    verbose: Annotated[
        bool,
        typer.Option("--verbose", help="Say which configuration and settings files are used."),
    ] = False,
) -> None:
    """Record, serve and replay MOOS logs for fleets of vehicles over Eclipse Zenoh."""
    global_settings.configure(settings, verbose)


def main() -> None:
    """Run the CLI; any FleetlogError becomes one sentence on stderr and exit status 1."""
    try:
        # Inside the guard: a Ctrl-C while the commands (and zenoh) load is a quiet exit too.
        from fleetlog.cli import commands

        commands.load(sys.argv[1:])  # the command being run registers itself (or all do)
        app()
    except FleetlogError as err:
        print(f"fleetlog: error: {err}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)
