"""``fleetlog fetch``: download sessions from vehicles, resumable and verified."""

from __future__ import annotations

import math
import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import (
    BarColumn,
    DownloadColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeRemainingColumn,
    TransferSpeedColumn,
)

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_seconds,
    checked_vehicle,
)
from fleetlog.cli.shore import open_client
from fleetlog.cli.tables import err_console, human_size
from fleetlog.errors import FleetlogError, FormatError, QueryError, UsageError
from fleetlog.shore import fetch as fetching
from fleetlog.shore.client import FleetClient
from fleetlog.wire.query import check_component

__all__ = ["fetch"]

_MAX_PARALLEL = 8


class _Bars(fetching.Progress):
    """One rich progress bar per vehicle (thread-safe: rich's Progress locks)."""

    def __init__(self, progress: Progress) -> None:
        self.progress = progress
        self.tasks: dict[str, TaskID] = {}
        self._lock = threading.Lock()

    def _task(self, vehicle: str) -> TaskID:
        with self._lock:
            task = self.tasks.get(vehicle)
            if task is None:
                task = self.progress.add_task(vehicle, total=None)
                self.tasks[vehicle] = task
            return task

    def total(self, vehicle: str, total: int) -> None:
        self.progress.update(self._task(vehicle), total=total)

    def advance(self, vehicle: str, amount: int) -> None:
        self.progress.advance(self._task(vehicle), amount)


def _targets(
    client: FleetClient, vehicle: str | None, session: str | None, latest: bool, every: bool
) -> list[tuple[str, str]]:
    """Return the (vehicle, session) pairs to fetch."""
    if every:
        up = client.vehicles()
        if not up:
            msg = "no vehicle is up (no recorder or serve token answered; check --connect / --mode)"
            raise QueryError(msg)
        found = client.latest_all()
        pairs: list[tuple[str, str]] = []
        for name in sorted(up):
            info = found.get(name)
            if info is None:
                print(f"fleetlog: warning: vehicle {name} does not serve its logs", file=sys.stderr)
            elif info.session is None:
                print(f"fleetlog: warning: vehicle {name} has no session", file=sys.stderr)
            else:
                pairs.append((name, info.session))
        return pairs
    assert vehicle is not None
    client.require(vehicle)
    if session is None:
        info = client.latest(vehicle)
        if info.session is None:
            msg = f"vehicle {vehicle} has no session to fetch"
            raise QueryError(msg)
        session = info.session
    return [(vehicle, session)]


def _report(outcome: fetching.FetchOutcome) -> str:
    counts: dict[str, int] = {}
    for item in outcome.files:
        counts[item.status] = counts.get(item.status, 0) + 1
    states = ", ".join(f"{n} {status}" for status, n in sorted(counts.items()))
    rate = outcome.received / outcome.seconds / 1e6 if outcome.seconds > 0 else 0.0
    line = (
        f"{outcome.vehicle}\t{outcome.session}\t{states}\t{human_size(outcome.received)} received"
        f" in {outcome.seconds:.1f} s ({rate:.0f} MB/s)\t{outcome.directory}"
    )
    if not outcome.complete:
        line += "\t(still being written: kept as .part; --follow waits for the end)"
    return line


@app.command()
def fetch(
    vehicle: Annotated[
        str | None,
        typer.Argument(
            metavar="VEHICLE", help="The vehicle (its MOOS community).", show_default=False
        ),
    ] = None,
    session: Annotated[
        str | None,
        typer.Argument(
            metavar="SESSION",
            help="The session to fetch [default: the latest].",
            show_default=False,
        ),
    ] = None,
    latest: Annotated[bool, typer.Option("--latest", help="Fetch the latest session.")] = False,
    every: Annotated[
        bool, typer.Option("--all", help="Fetch from every vehicle up (with --latest).")
    ] = False,
    out: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            metavar="DIR",
            help="Where the session directories go (with --all: DIR/VEHICLE/SESSION).",
        ),
    ] = Path(),
    follow: Annotated[
        bool,
        typer.Option(
            "--follow",
            help="For a session still being written: keep fetching until it completes.",
        ),
    ] = False,
    rate: Annotated[
        float | None,
        typer.Option(
            "--rate",
            metavar="MB/S",
            help="Transfer at most this many MB/s per vehicle [default: no limit].",
        ),
    ] = None,
    retry_for: Annotated[
        float,
        typer.Option(
            "--retry-for",
            metavar="SECONDS",
            help="How long to keep retrying a vehicle that stopped answering.",
        ),
    ] = fetching.RETRY_FOR,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Download a vehicle's session (or every vehicle's latest) in pLogger's layout.

    Files arrive as FILE.part and become FILE only once their sha256 matches the vehicle's;
    an interrupted fetch (Ctrl-C, a dropped link, a stopped vehicle) resumes when the same
    command is run again. A session still being written is fetched as far as it goes (kept
    as .part), unless --follow waits for its end.
    """
    if every and (vehicle is not None or session is not None):
        msg = "--all fetches every vehicle's latest session; give no VEHICLE or SESSION with it"
        raise UsageError(msg)
    if every and not latest:
        msg = "--all fetches each vehicle's latest session: write fetch --all --latest"
        raise UsageError(msg)
    if not every and vehicle is None:
        msg = "name a VEHICLE, or use --all --latest"
        raise UsageError(msg)
    if latest and session is not None:
        msg = f"give either --latest or a SESSION ({session}), not both"
        raise UsageError(msg)
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        msg = f"--rate must be a positive number of MB/s, not {rate:g}"
        raise UsageError(msg)
    checked_seconds(retry_for, "--retry-for")
    if vehicle is not None:
        checked_vehicle(vehicle, "VEHICLE")
    try:
        if session is not None:
            check_component(session, "session")
    except FormatError as err:
        raise UsageError(str(err)) from None
    cancel = threading.Event()
    with open_client(root, mode, connect, listen, config, no_multicast_scouting) as client:
        pairs = _targets(client, vehicle, session, latest, every)
        if not pairs:
            return
        with Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            DownloadColumn(),
            TransferSpeedColumn(),
            TimeRemainingColumn(),
            console=err_console(),
            transient=False,
        ) as bar:
            bars = _Bars(bar)
            pool = ThreadPoolExecutor(min(_MAX_PARALLEL, len(pairs)))
            futures: dict[str, Future[fetching.FetchOutcome]] = {}
            for name, wanted in pairs:
                target = out / name if every else out
                if every:
                    try:
                        check_component(name, "vehicle")
                    except FormatError as err:
                        print(f"fleetlog: warning: skipped: {err}", file=sys.stderr)
                        continue
                futures[name] = pool.submit(
                    fetching.fetch_session,
                    client,
                    name,
                    wanted,
                    target,
                    follow=follow,
                    progress=bars,
                    max_rate=rate * 1e6 if rate else None,
                    retry_for=retry_for,
                    cancel=cancel,
                )
            try:
                results = _collect(futures)
            except KeyboardInterrupt:
                cancel.set()
                pool.shutdown(wait=True)
                print("fleetlog: interrupted; the same command resumes", file=sys.stderr)
                raise
            pool.shutdown(wait=True)
    _finish(results)


def _collect(
    futures: dict[str, Future[fetching.FetchOutcome]],
) -> list[tuple[str, fetching.FetchOutcome | FleetlogError]]:
    results: list[tuple[str, fetching.FetchOutcome | FleetlogError]] = []
    for name, future in futures.items():
        try:
            results.append((name, future.result()))
        except FleetlogError as err:
            results.append((name, err))
    return results


def _finish(results: list[tuple[str, fetching.FetchOutcome | FleetlogError]]) -> None:
    failed: list[FleetlogError] = []
    for _name, result in results:
        if isinstance(result, FleetlogError):
            failed.append(result)
        else:
            print(_report(result))
    if len(failed) == 1 and len(results) == 1:
        raise failed[0]
    for err in failed:
        print(f"fleetlog: error: {err}", file=sys.stderr)
    if failed:
        msg = f"{len(failed)} of {len(results)} vehicle(s) failed; the same command resumes them"
        raise QueryError(msg)
