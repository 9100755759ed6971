"""``fleetlog collect``: the shore service that mirrors every vehicle's sessions."""

from __future__ import annotations

import json
import math
import re
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_seconds,
)
from fleetlog.cli.shore import (
    WAIT,
    Expect,
    MinFreeDisk,
    Wait,
    checked_expect,
    checked_min_free,
    open_client,
)
from fleetlog.cli.tables import console, human_size, human_time, plain
from fleetlog.errors import QueryError, UsageError
from fleetlog.shore.collect import CollectOptions, Collector
from fleetlog.shore.holdings import ArchiveHoldings, holdings
from fleetlog.transport.notify import Notifier, Watchdog

__all__ = ["collect", "parse_rate"]

_RATE = re.compile(r"([0-9]*\.?[0-9]+(?:e[+-]?[0-9]+)?)\s*([kmg]?)(b|bit|bps|B|ps)?", re.I)
_SCALE = {"": 1.0, "k": 1e3, "m": 1e6, "g": 1e9}


def parse_rate(text: str, option: str) -> float:
    """Read a rate: ``1Mbit`` (bits/s), ``125kB`` (bytes/s), or a plain number of MB/s.

    Raises:
        UsageError: not a positive rate.
    """
    match = _RATE.fullmatch(text.strip())
    value = float(match.group(1)) if match else math.nan
    if not match or not math.isfinite(value) or value <= 0:
        msg = f"{option} must be a positive rate such as 1Mbit, 125kB or 0.5 (MB/s), not {text!r}"
        raise UsageError(msg)
    prefix, unit = match.group(2).lower(), match.group(3) or ""
    if not prefix and not unit:
        return value * 1e6  # a plain number is MB/s, as fetch --rate
    if unit.lower() in ("bit", "bps") or unit == "b":
        return value * _SCALE[prefix] / 8  # bits per second
    return value * _SCALE[prefix]


def _ago(seen: float | None) -> str:
    if seen is None:
        return "never"
    age = max(0.0, time.time() - seen)
    if age < 90:
        return f"{age:.0f} s ago"
    if age < 5400:
        return f"{age / 60:.0f} min ago"
    return human_time(seen)


def _table(view: ArchiveHoldings) -> Table:
    table = Table(box=None, pad_edge=False)
    for column in ("VEHICLE", "LAST SEEN", "ON SHORE", "ONLY ON VEHICLE", "IN FLIGHT", "ACKED"):
        table.add_column(column, no_wrap=True)
    for vehicle in view.vehicles:
        shore = vehicle.on_shore
        cut = sum(s.state == "cut" for s in shore)
        on_shore = f"{len(shore)} ({human_size(sum(s.here for s in shore))})"
        if cut:
            on_shore += f", {cut} cut"
        only = vehicle.only_on_vehicle
        only_text = f"{len(only)} ({human_size(vehicle.missing_bytes())})" if only else "-"
        flights = []
        for flight in vehicle.in_flight:
            here, size = flight.get("here"), flight.get("size")
            share = f" {here * 100 // size}%" if isinstance(here, int) and size else ""
            flights.append(f"{flight.get('session')} ({flight.get('how')}{share})")
        acked = sum(s.acked is not None for s in vehicle.sessions)
        pruned = sum(s.pruned is not None for s in vehicle.sessions)
        seen = "up now" if vehicle.up else _ago(vehicle.seen)
        table.add_row(
            plain(vehicle.vehicle),
            seen,
            on_shore,
            only_text,
            plain(", ".join(flights) or "-"),
            f"{acked}" + (f", {pruned} pruned" if pruned else ""),
        )
    return table


def _status(archive: Path, as_json: bool) -> None:
    view = holdings(archive)
    if as_json:
        print(json.dumps(view.as_json(), indent=1))
        return
    out = console()
    state = "a collector runs on it" if view.running else "no collector runs on it now"
    out.print(plain(f"archive {archive}: {state}"))
    if not view.vehicles:
        out.print("no vehicle collected yet")
    else:
        out.print(_table(view))
    for vehicle in view.vehicles:
        if vehicle.error:
            out.print(plain(f"{vehicle.vehicle}: last error: {vehicle.error}"))
    for name, why in sorted(view.unreadable.items()):
        out.print(plain(f"{name}: record unreadable: {why}"))


def _say(text: str) -> None:
    print(f"fleetlog collect: {text}", file=sys.stderr, flush=True)


@app.command()
def collect(
    archive: Annotated[
        Path,
        typer.Argument(
            metavar="ARCHIVE",
            help="The shore archive: ARCHIVE/VEHICLE/SESSION/, as fetch --all lays it out.",
            show_default=False,
        ),
    ],
    status: Annotated[
        bool,
        typer.Option(
            "--status",
            help="Show the fleet view of ARCHIVE and exit: per vehicle, what is on shore, what"
            " only on the vehicle, what is in flight, when it was last seen.",
        ),
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="With --status: print JSON.")] = False,
    once: Annotated[
        bool,
        typer.Option(
            "--once",
            help="Collect what the vehicles up hold now, then exit (non-zero if a vehicle"
            " failed or a session is not all here); the session being recorded is taken as"
            " far as it goes.",
        ),
    ] = False,
    max_rate: Annotated[
        str | None,
        typer.Option(
            "--max-rate",
            metavar="RATE",
            help="At most this rate per vehicle: 1Mbit, 125kB, or a number of MB/s"
            " [default: as the link allows, leaving room for commands].",
        ),
    ] = None,
    max_total_rate: Annotated[
        str | None,
        typer.Option(
            "--max-total-rate",
            metavar="RATE",
            help="At most this rate over every vehicle together.",
        ),
    ] = None,
    prune: Annotated[
        bool,
        typer.Option(
            "--prune-after-collect",
            help="Ask each vehicle to delete the sessions it acknowledged (every file on shore,"
            " verified by sha256); never the one being recorded, nor one being fetched.",
        ),
    ] = False,
    poll: Annotated[
        float,
        typer.Option(
            "--poll", metavar="SECONDS", help="How often the session being recorded is looked at."
        ),
    ] = 2.0,
    rescan: Annotated[
        float,
        typer.Option(
            "--rescan",
            metavar="SECONDS",
            help="How often a vehicle whose sessions are all here is listed again.",
        ),
    ] = 10.0,
    retry_for: Annotated[
        float,
        typer.Option(
            "--retry-for",
            metavar="SECONDS",
            help="How long a transfer rides out a vehicle that stopped answering.",
        ),
    ] = 30.0,
    min_free_disk: MinFreeDisk = "512MiB",
    expect: Expect = None,
    wait: Wait = WAIT,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Mirror every vehicle's sessions into ARCHIVE, by themselves, as vehicles come and go.

    Runs as the shore's service (deploy/systemd/fleetlog-collect.service) until SIGTERM or
    Ctrl-C. Each vehicle is collected from the moment its recorder or log server is up:
    the session being recorded is followed as it grows, the others are fetched newest
    first (small files before alogs), resumable and verified by sha256, at Zenoh's
    background priority so the link's commands and telemetry keep flowing. Closed sessions
    are marked complete, cut ones cut; each is then acknowledged to the vehicle. A restart
    never fetches a file twice.
    """
    if status:
        _status(archive, as_json)
        return
    if as_json:
        msg = "--json goes with --status"
        raise UsageError(msg)
    for value, option in ((poll, "--poll"), (rescan, "--rescan"), (retry_for, "--retry-for")):
        checked_seconds(value, option, zero=False)
    options = CollectOptions(
        max_rate=parse_rate(max_rate, "--max-rate") if max_rate else None,
        max_total_rate=parse_rate(max_total_rate, "--max-total-rate") if max_total_rate else None,
        prune=prune,
        once=once,
        expect=checked_expect(expect),
        poll=poll,
        rescan=rescan,
        retry_for=retry_for,
        min_free=checked_min_free(min_free_disk),
    )
    stop = threading.Event()
    notifier = Notifier()
    watchdog = Watchdog(notifier)

    def on_signal(signum: int, frame: object) -> None:
        notifier.stopping("keeping what is in flight for the next start")
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        collector = Collector(client, archive, options, log=_say)
        _say(f"collecting into {archive}")
        notifier.ready(f"collecting into {archive}")
        report = collector.run(stop, tick=watchdog.kick if watchdog.enabled else lambda: None)
    if not once:
        _say("stopped")
        return
    _say(
        f"{len(report.completed)} session(s) completed, {len(report.acked)} acknowledged,"
        f" {len(report.pruned)} pruned, {human_size(report.received)} received"
    )
    problems = []
    if report.missing:
        problems.append(f"not up: {', '.join(report.missing)}")
    if report.failed:
        problems.append("failed: " + "; ".join(f"{v}: {w}" for v, w in report.failed.items()))
    if report.pending:
        problems.append(f"not all here yet: {', '.join(sorted(report.pending))}")
    if problems:
        raise QueryError("; ".join(problems))
