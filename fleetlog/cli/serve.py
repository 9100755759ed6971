"""``fleetlog serve``: serve a log root's sessions without recording (old or foreign logs)."""

from __future__ import annotations

import signal
import socket
import sys
import threading
from pathlib import Path
from typing import Annotated

import typer

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
from fleetlog.errors import UsageError
from fleetlog.query.server import LogServer
from fleetlog.query.standby import Standby
from fleetlog.storage.catalog import ALOG_SUFFIXES, LogCatalog
from fleetlog.storage.heap import HeapKeeper
from fleetlog.transport.queries import ZenohSession
from fleetlog.transport.session import open_session

__all__ = ["serve"]


@app.command()
def serve(
    log_root: Annotated[
        Path,
        typer.Argument(
            metavar="LOGROOT", help="Directory holding the session directories.", show_default=False
        ),
    ],
    vehicle: Annotated[
        str | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="NAME",
            help="Vehicle to serve as [default: the community that wrote the latest session,"
            " else the host name].",
        ),
    ] = None,
    hint: Annotated[
        Path | None,
        typer.Option(
            "--hint",
            metavar="FILE",
            help="The .LastOpenedMOOSLogDirectory file naming the latest session"
            " [default: the one in LOGROOT, else in its parent].",
        ),
    ] = None,
    standby: Annotated[
        bool,
        typer.Option(
            "--standby",
            help="Serve only while no recorder of the vehicle serves its logs: run it beside"
            " the recorder, on its log root, so the logs stay reachable after the recorder"
            " stops (a fetch --follow then ends verified).",
        ),
    ] = False,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Serve the MOOS log sessions under LOGROOT to the shore, as a recorder does.

    Works on directories written by real pLogger as well as by fleetlog. Stop it with Ctrl-C
    or SIGTERM. With --standby it runs beside the vehicle's recorder and takes over when the
    recorder stops, so a vehicle's logs stay reachable whatever the recorder does.
    """
    key_root = checked_root(root)
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    if not log_root.is_dir():
        msg = f"log root {log_root} is not a directory"
        raise UsageError(msg)
    if hint is not None and not hint.is_file():
        what = "is not a file" if hint.exists() else "does not exist"
        msg = f"hint file {hint} {what}"
        raise UsageError(msg)
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    catalog = LogCatalog(log_root, vehicle="", hint=hint)
    name = vehicle or catalog.guess_vehicle() or socket.gethostname().split(".")[0] or "vehicle"
    catalog.vehicle = name
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    session = open_session(zopts)
    try:
        if standby:
            _standby(session, catalog, key_root, name, log_root, stop)
            return
        with HeapKeeper(), LogServer(session, catalog, root=key_root, announce=True):
            _announce(catalog, log_root, name)
            while not stop.wait(0.5):
                pass
    finally:
        session.close()
        print("fleetlog: stopped serving", file=sys.stderr)


def _announce(catalog: LogCatalog, log_root: Path, name: str) -> None:
    sessions = catalog.session_names()
    latest = catalog.latest()
    if not sessions:
        # A session directory given as LOGROOT is the usual slip: say what to serve.
        inner = any(p.name.endswith(ALOG_SUFFIXES) for p in log_root.iterdir())
        advice = f"; it is a session itself: serve {log_root.resolve().parent}" if inner else ""
        print(
            f"fleetlog: warning: {log_root} holds no session directory (a directory"
            f" with an .alog, .alog.gz or .alog.zst){advice}",
            file=sys.stderr,
        )
    print(
        f"fleetlog: serving {log_root} as vehicle {name!r}: {len(sessions)} session(s),"
        f" latest {latest.session or '-'} ({latest.how}) (Ctrl-C to stop)",
        file=sys.stderr,
        flush=True,
    )


def _standby(
    session: ZenohSession,
    catalog: LogCatalog,
    root: str,
    name: str,
    log_root: Path,
    stop: threading.Event,
) -> None:
    def on_change(serving: bool, why: str) -> None:
        if serving:
            print(f"fleetlog: {why}: taking over", file=sys.stderr, flush=True)
            _announce(catalog, log_root, name)
        else:
            print(f"fleetlog: standing by: {why}", file=sys.stderr, flush=True)

    print(
        f"fleetlog: standing by for vehicle {name!r}'s recorder; serving {log_root} whenever"
        " it does not (Ctrl-C to stop)",
        file=sys.stderr,
        flush=True,
    )
    Standby(session, catalog, root=root, vehicle=name, on_change=on_change).run(stop)
