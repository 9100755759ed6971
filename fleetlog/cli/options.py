"""The Zenoh options every command that talks to Zenoh shares (as zenoh-python's examples)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from fleetlog.cli.settings import say, settings
from fleetlog.errors import FormatError, TransportError, UsageError
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.keys import DEFAULT_ROOT, check_root

__all__ = [
    "Config",
    "Connect",
    "Listen",
    "Mode",
    "NoScouting",
    "Root",
    "checked_seconds",
    "checked_vehicle",
    "session_options",
]

_ZENOH = "Zenoh"

Mode = Annotated[
    str | None,
    typer.Option(
        "-m",
        "--mode",
        metavar="MODE",
        help="Zenoh session mode: peer (default), client or router.",
        rich_help_panel=_ZENOH,
    ),
]
Connect = Annotated[
    list[str] | None,
    typer.Option(
        "-e",
        "--connect",
        metavar="ENDPOINT",
        help="Endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).",
        rich_help_panel=_ZENOH,
    ),
]
Listen = Annotated[
    list[str] | None,
    typer.Option(
        "-l",
        "--listen",
        metavar="ENDPOINT",
        help="Endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).",
        rich_help_panel=_ZENOH,
    ),
]
Config = Annotated[
    Path | None,
    typer.Option(
        "-c",
        "--config",
        metavar="FILE",
        help="A Zenoh JSON5 configuration file [default: $ZENOH_CONFIG, else"
        " /etc/fleetlog/zenoh.json5 if present].",
        rich_help_panel=_ZENOH,
    ),
]
NoScouting = Annotated[
    bool,
    typer.Option(
        "--no-multicast-scouting",
        help="Do not discover peers by multicast.",
        rich_help_panel=_ZENOH,
    ),
]


def _root_setting(ctx: typer.Context, param: typer.CallbackParam, value: str) -> str:
    """``--root`` not given: the settings file's root, if it names one."""
    source = ctx.get_parameter_source(param.name or "root")
    if source is not None and source.name == "DEFAULT":
        return settings().get("root") or value
    return value


Root = Annotated[
    str,
    typer.Option(
        "--root",
        metavar="ROOT",
        help="Key root of the fleet's keys [default: the settings file's root, else fleet].",
        rich_help_panel=_ZENOH,
        callback=_root_setting,
        show_default=False,
    ),
]


def session_options(
    mode: str | None,
    connect: list[str] | None,
    listen: list[str] | None,
    config: Path | None,
    no_multicast_scouting: bool,
) -> SessionOptions:
    """Build SessionOptions from the shared command-line options.

    Raises:
        UsageError: an option is unusable (unknown mode, missing config file).
    """
    if mode is not None and mode not in ("peer", "client", "router"):
        msg = f"--mode must be peer, client or router, not {mode!r}"
        raise UsageError(msg)
    if config is not None and not config.is_file():
        what = "is not a file" if config.exists() else "does not exist"
        msg = f"Zenoh configuration file {config} {what}"
        raise UsageError(msg)
    options = SessionOptions(
        mode=mode,
        connect=tuple(connect or ()),
        listen=tuple(listen or ()),
        config=config,
        multicast_scouting=not no_multicast_scouting,
    )
    try:
        source = options.source()
    except TransportError as err:
        raise UsageError(str(err)) from None
    say(f"Zenoh configuration: {source.describe()}")
    say(f"settings: {settings().describe()}")
    return options


def checked_root(root: str) -> str:
    """Validate ``--root``.

    Raises:
        UsageError: the root cannot prefix keys.
    """
    try:
        return check_root(root)
    except FormatError as err:
        raise UsageError(str(err)) from None


def checked_seconds(value: float, option: str, *, zero: bool = True) -> float:
    """Validate a duration option: a finite number of seconds, not negative.

    Args:
        value: what was given.
        option: the option's name, for the message.
        zero: whether 0 is allowed.

    Raises:
        UsageError: NaN, infinite, negative, or 0 where it is not allowed.
    """
    if not math.isfinite(value) or value < 0 or (value == 0 and not zero):
        least = "0 or more" if zero else "more than 0"
        msg = f"{option} must be a number of seconds, {least}, not {value:g}"
        raise UsageError(msg)
    return value


def checked_vehicle(name: str, option: str) -> str:
    """Validate a vehicle name given on the command line.

    Raises:
        UsageError: the name is empty or blank.
    """
    if not name.strip():
        msg = f"{option} needs a vehicle name, not {name!r}"
        raise UsageError(msg)
    return name


DEFAULT = DEFAULT_ROOT
