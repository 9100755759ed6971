"""``fleetlog bridge``: a MOOS community on Zenoh, and Zenoh's samples in its MOOSDB."""

from __future__ import annotations

import dataclasses
import signal
import sys
from pathlib import Path
from typing import Annotated

import typer

from fleetlog.bridge.service import BridgeOptions, BridgeService
from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_root,
    checked_vehicle,
    session_options,
)
from fleetlog.cli.record import read_mission
from fleetlog.errors import UsageError
from fleetlog.moos.bridge_config import BRIDGE_APP, bridge_config
from fleetlog.moos.protocol import DEFAULT_MAX_PACKET

__all__ = ["bridge"]

_MOOS = "MOOS"


def _say(text: str) -> None:
    print(f"fleetlog: bridge: {text}", file=sys.stderr, flush=True)


@app.command()
def bridge(
    mission: Annotated[
        Path | None,
        typer.Argument(
            metavar="MISSION",
            help="MOOS mission file: ServerHost, ServerPort, Community and an optional"
            " 'ProcessConfig = fleetlog_bridge' block (ToZenoh, FromZenoh)"
            " [default: none, localhost:9000, every variable both ways].",
            show_default=False,
        ),
    ] = None,
    host: Annotated[
        str | None,
        typer.Option(
            "--host",
            metavar="HOST",
            help="The MOOSDB's host [default: ServerHost].",
            rich_help_panel=_MOOS,
        ),
    ] = None,
    port: Annotated[
        int | None,
        typer.Option(
            "--port",
            metavar="PORT",
            help="The MOOSDB's port [default: ServerPort, 9000].",
            rich_help_panel=_MOOS,
        ),
    ] = None,
    vehicle: Annotated[
        str | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="NAME",
            help="Vehicle whose keys are bridged [default: the mission's Community, else the"
            " MOOSDB's].",
            rich_help_panel=_MOOS,
        ),
    ] = None,
    moos_name: Annotated[
        str,
        typer.Option(
            "--moos-name",
            metavar="NAME",
            help="The bridge's name in the MOOS community.",
            rich_help_panel=_MOOS,
        ),
    ] = BRIDGE_APP,
    max_packet_mib: Annotated[
        float,
        typer.Option(
            "--max-packet",
            metavar="MiB",
            help="Largest MOOS packet accepted and message posted, in MiB; larger ones are"
            " skipped and counted.",
            rich_help_panel=_MOOS,
        ),
    ] = DEFAULT_MAX_PACKET / (1 << 20),
    no_wait: Annotated[
        bool,
        typer.Option(
            "--no-wait",
            help="Fail if the MOOSDB is not up at the start instead of waiting for it.",
            rich_help_panel=_MOOS,
        ),
    ] = False,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Bridge a MOOS community to Zenoh, both ways: today's MOOS-IvP vehicles join the fleet.

    Every MOOS variable (the MOOSDB's DB_* included) is published on <root>/<vehicle>/var/<VAR>
    with its time, source, aux source and community; what other Zenoh sessions publish for
    the vehicle (fleetlog poke, replay --into-live, the Python API) is posted into the MOOSDB
    under its original source and time. The bridge never sends a message back where it came
    from, drops the MOOSDB's echoes of its own posts, and never posts a value whose type
    differs from the variable's type in the MOOSDB (MOOS would drop it silently): it counts
    it and says so on MOOS_DEBUG. It reconnects by itself when the MOOSDB or the Zenoh router
    goes away, and counts what it could not forward meanwhile. Stop it with Ctrl-C.
    """
    key_root = checked_root(root)
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    if port is not None and not 0 < port < 65536:
        msg = f"--port must be a TCP port (1-65535), not {port}"
        raise UsageError(msg)
    if not moos_name.strip() or any(c in moos_name for c in ",=\0"):
        msg = f"--moos-name must be a MOOS name without ',', '=' or NUL, not {moos_name!r}"
        raise UsageError(msg)
    if not 0.001 <= max_packet_mib <= 2047:
        msg = f"--max-packet must be between 0.001 and 2047 MiB, not {max_packet_mib:g}"
        raise UsageError(msg)
    parsed = read_mission(mission) if mission is not None else None
    cfg = bridge_config(parsed, moos_name)
    if parsed is not None and parsed.block(moos_name) is None:
        _say(f"{mission} has no 'ProcessConfig = {moos_name}' block: every variable, both ways")
    cfg = dataclasses.replace(
        cfg,
        host=host if host is not None else cfg.host,
        port=port if port is not None else cfg.port,
    )
    service = BridgeService(
        cfg,
        BridgeOptions(
            vehicle=vehicle,
            root=key_root,
            zenoh=zopts,
            name=moos_name,
            max_packet=int(max_packet_mib * (1 << 20)),
            wait_first=not no_wait,
        ),
        on_say=_say,
    )

    def on_signal(signum: int, frame: object) -> None:
        service.stop()
        signal.signal(signum, signal.SIG_DFL)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    stats = service.run()
    s = stats
    _say(
        f"stopped: MOOS -> Zenoh {s.to_zenoh} of {s.from_moos} (echoes {s.echoes}, "
        f"re-deliveries {s.redelivered}, not forwarded {s.unforwarded_to_zenoh}); "
        f"Zenoh -> MOOS {s.to_moos} of {s.from_zenoh} (type clashes {s.type_clashes}, "
        f"not forwarded {s.unforwarded_to_moos}, too large {s.too_large}, "
        f"unconfirmed {s.unconfirmed})"
    )
