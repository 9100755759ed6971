"""``fleetlog fetch``: download sessions from vehicles, resumable and verified."""

from __future__ import annotations

import math
import sys
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
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
from fleetlog.cli.shore import (
    WAIT,
    Expect,
    MinFreeDisk,
    Wait,
    checked_min_free,
    discover,
    finish,
    open_client,
    warn,
)
from fleetlog.cli.tables import err_console, human_size
from fleetlog.errors import FleetlogError, FormatError, QueryError, UsageError
from fleetlog.shore import fetch as fetching
from fleetlog.shore import transfer
from fleetlog.shore.client import FleetClient
from fleetlog.shore.report import FleetReport
from fleetlog.wire.query import check_component

__all__ = ["fetch"]

_MAX_PARALLEL = 8


class _Bars(transfer.Progress):
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


@dataclass(frozen=True)
class _Target:
    """One session to fetch from one process, and where it goes."""

    vehicle: str
    session: str
    directory: Path
    server: str | None = None

    @property
    def label(self) -> str:
        return self.vehicle if self.server is None else f"{self.vehicle}@{self.server}"


def _place(out: Path, vehicle: str, server: str | None, every: bool, conflict: bool) -> Path:
    """Where a vehicle's sessions go: DIR, DIR/VEHICLE (--all), DIR/VEHICLE@ZID (conflict)."""
    if conflict:
        return out / f"{vehicle}@{server}"
    return out / vehicle if every else out


def _answers_of(
    client: FleetClient, vehicle: str, server: str | None
) -> list[tuple[str | None, str | None]]:
    """Return ``(server, latest session)`` for each process that answers for the vehicle."""
    if server is not None:
        info = client.latest(vehicle, server=server)
        return [(info.server, info.session)]
    return [(a.server, a.session) for a in client.latest_answers(vehicle)]


def _every(
    client: FleetClient, out: Path, expect: list[str] | None, report: FleetReport
) -> list[_Target]:
    """The latest session of every vehicle up, one target per answering process."""
    view = discover(client, expect)
    report.missing = view.missing
    if not view.vehicles:
        if report.missing:
            return []
        msg = "no vehicle is up (no recorder or serve token answered; check --connect / --mode)"
        raise QueryError(msg)
    found = client.latest_all()
    targets: list[_Target] = []
    for name in view.names:
        try:
            check_component(name, "vehicle")
        except FormatError as err:
            report.failed[name] = f"cannot be a directory name: {err}"
            continue
        answers = [(a.server, a.session) for a in found.get(name, [])]
        if not answers:
            # Not in the fleet-wide answer: ask it alone (a vehicle that just came up).
            try:
                answers = _answers_of(client, name, None)
            except QueryError as err:
                report.failed[name] = str(err)
                continue
        conflict = len(answers) > 1
        if conflict:
            servers = ", ".join(sorted(str(a[0]) for a in answers))
            warn(f"vehicle {name}: {len(answers)} processes answer ({servers}); fetching each")
        for server, session in answers:
            place = _place(out, name, server, True, conflict)
            target = _Target(name, session or "", place, server if conflict else None)
            if session is None:
                report.skipped[target.label] = "has no session"
            else:
                targets.append(target)
    return targets


def _one(
    client: FleetClient, vehicle: str, session: str | None, out: Path, server: str | None
) -> list[_Target]:
    """The session (or latest session) of one vehicle, from each process that holds it."""
    client.require(vehicle)
    answers = _answers_of(client, vehicle, server)
    conflict = len(answers) > 1
    targets: list[_Target] = []
    for zid, latest in answers:
        pinned = zid if conflict or server is not None else None
        wanted = session or latest
        if wanted is None:
            continue
        if session is not None and conflict:
            try:
                client.session(vehicle, session, server=zid)
            except QueryError:
                continue  # the other recorder holds it
        place = _place(out, vehicle, zid, False, conflict)
        targets.append(_Target(vehicle, wanted, place, pinned))
    if not targets:
        what = f"no session {session!r}" if session is not None else "no session to fetch"
        msg = f"vehicle {vehicle} has {what}"
        raise QueryError(msg)
    if conflict:
        servers = ", ".join(sorted(str(a[0]) for a in answers))
        warn(
            f"vehicle {vehicle}: {len(answers)} processes answer ({servers}); fetching"
            f" from each into {out}/{vehicle}@ZID/"
        )
    return targets


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
    elif outcome.state == "cut":
        line += "\t(cut: its recorder died with it open; what it wrote is all there is)"
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
            help="For a session still being written: keep fetching until it ends (closed, or"
            " cut by a crash), then verify. Run fleetlog serve --standby beside the recorder"
            " so the end can still be fetched once the recorder stops.",
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
    server: Annotated[
        str | None,
        typer.Option(
            "--server",
            metavar="ZID",
            help="Fetch from this process only (its Zenoh id), when two recorders answer for"
            " the vehicle.",
        ),
    ] = None,
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
    """Download a vehicle's session (or every vehicle's latest) in pLogger's layout.

    Files arrive as FILE.part and become FILE only once their sha256 matches the vehicle's;
    an interrupted fetch (Ctrl-C, a dropped link, a stopped vehicle) resumes when the same
    command is run again. A session still being written is fetched as far as it goes (kept
    as .part), unless --follow waits for its end.

    With --all it first waits for the fleet (every --expect'ed vehicle, else until no new
    vehicle appears), and exits non-zero naming each vehicle that was not up or failed.
    When two processes answer for one vehicle (two recorders after a partition healed),
    each one's session goes to DIR/VEHICLE@ZID/.
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
    min_free = checked_min_free(min_free_disk)
    if expect and not every:
        msg = "--expect names the vehicles --all should find; fetch VEHICLE waits for VEHICLE"
        raise UsageError(msg)
    if server is not None and every:
        msg = "--server names one process of one vehicle; give VEHICLE instead of --all"
        raise UsageError(msg)
    if vehicle is not None:
        checked_vehicle(vehicle, "VEHICLE")
    try:
        if session is not None:
            check_component(session, "session")
    except FormatError as err:
        raise UsageError(str(err)) from None
    cancel = threading.Event()
    report = FleetReport("fetched")
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        if every:
            targets = _every(client, out, expect, report)
        else:
            assert vehicle is not None
            targets = _one(client, vehicle, session, out, server)
        if not targets:
            finish(report)
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
            pool = ThreadPoolExecutor(min(_MAX_PARALLEL, len(targets)))
            futures: dict[str, Future[fetching.FetchOutcome]] = {}
            for target in targets:
                futures[target.label] = pool.submit(
                    fetching.fetch_session,
                    client,
                    target.vehicle,
                    target.session,
                    target.directory,
                    follow=follow,
                    progress=bars,
                    max_rate=rate * 1e6 if rate else None,
                    retry_for=retry_for,
                    cancel=cancel,
                    server=target.server,
                    min_free=min_free,
                )
            try:
                results = _collect(futures)
            except KeyboardInterrupt:
                cancel.set()
                pool.shutdown(wait=True)
                print("fleetlog: interrupted; the same command resumes", file=sys.stderr)
                raise
            pool.shutdown(wait=True)
    _finish(results, report, single=not every and len(targets) == 1)


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


def _finish(
    results: list[tuple[str, fetching.FetchOutcome | FleetlogError]],
    report: FleetReport,
    *,
    single: bool,
) -> None:
    for label, result in results:
        if isinstance(result, FleetlogError):
            if single:
                raise result
            report.failed[label] = str(result)
        else:
            print(_report(result))
            report.done[label] = "fetched" if result.complete else "partial"
    finish(report)
