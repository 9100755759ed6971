"""``fleetlog collect``: every vehicle's sessions reach the shore archive by themselves.

The collector watches the fleet's liveliness tokens (:mod:`fleetlog.shore.discovery`) and
runs one worker per vehicle that is up, started the moment its token appears (a vehicle
coming into range, a recorder starting) and ended when its link stops answering. A worker
goes in rounds:

1. list the vehicle's sessions (``brief``: names, files, sizes, states; no alog read);
2. **follow** the session being recorded (one follower thread: ``fetch_session(follow=True)``,
   which takes what is appended until the session is closed or cut);
3. fetch the others **newest first**, in two passes: first every session's small files
   (metadata, ylog, slog, mission copy...), then the alogs, each through
   :func:`~fleetlog.shore.fetch.fetch_session` (resumable ``.part`` files, verified by
   sha256, at Zenoh's background priority, paced by a :class:`~fleetlog.shore.pacing.LinkPacer`
   so commands and telemetry keep flowing on a shared radio link, under ``--max-rate``);
4. mark each session whose every file is here and verified ``complete`` (or ``cut``, from
   its metadata) in the archive's record (:mod:`fleetlog.storage.archive`), and
   **acknowledge** it to the vehicle's recorder (``ack``, by sha256); with ``prune``, ask
   the vehicle's retention to delete what it acknowledged (``control/prune``);
5. wait (``rescan`` seconds) and look again.

A session already complete in the record is never fetched again, so a restarted collector
resumes where it was: complete sessions cost a listing, partial ones continue their
``.part`` files. A link cut mid-file fails the fetch after ``retry_for`` seconds with the
``.part`` kept; the worker tries again while the vehicle's token is up, and the next worker
resumes when it comes back.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import FormatError, QueryError, StorageError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.collect_rounds import ArchivePlace, VehicleWorker
from fleetlog.shore.fetch import FetchOutcome
from fleetlog.shore.pacing import RateLimit
from fleetlog.storage.archive import (
    CUT,
    ArchiveLock,
    check_vehicle_dir,
)
from fleetlog.storage.reserve import DEFAULT_SHORE_RESERVE

__all__ = ["CollectOptions", "CollectReport", "Collector"]

#: how often the collector looks at the fleet's tokens and writes its records
_TICK = 0.5
_SAVE_EVERY = 2.0


@dataclass(frozen=True)
class CollectOptions:
    """How the collector runs.

    Attributes:
        max_rate: bytes per second per vehicle at most (None: no cap).
        max_total_rate: bytes per second over every vehicle at most.
        prune: ask each vehicle to delete what it acknowledged.
        once: collect what is there once and return (the current session as far as it
            goes, not followed), instead of running until stopped.
        expect: vehicles to wait for (with ``once``).
        poll: seconds between looks at the session being recorded.
        rescan: seconds between looks at a vehicle whose sessions are all here.
        retry_for: seconds a fetch rides out a vehicle that stopped answering.
        target_delay: the extra delay (seconds) transfers may add to the link's round trip.
        source: how acknowledgements name the collector.
        min_free: bytes left free on the archive's disk: a transfer that would go below
            stops (the vehicle's round fails, said, and is retried with the others).
    """

    max_rate: float | None = None
    max_total_rate: float | None = None
    prune: bool = False
    once: bool = False
    expect: tuple[str, ...] = ()
    poll: float = 2.0
    rescan: float = 10.0
    retry_for: float = 30.0
    target_delay: float = 0.1
    source: str = "fleetlog collect"
    min_free: int = DEFAULT_SHORE_RESERVE


@dataclass
class CollectReport:
    """What a ``once`` run did (a running service reports through its log).

    Attributes:
        completed: ``vehicle/session`` newly complete or cut on shore.
        acked: ``vehicle/session`` acknowledged by the vehicle.
        pruned: ``vehicle/session`` deleted by the vehicle's retention.
        failed: vehicle → what went wrong.
        missing: expected vehicles that were not up.
        pending: ``vehicle/session`` not all here yet (being recorded, or failed).
        received: bytes received.
    """

    completed: list[str] = field(default_factory=list)
    acked: list[str] = field(default_factory=list)
    pruned: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    pending: list[str] = field(default_factory=list)
    received: int = 0


class Collector:
    """Mirrors every vehicle's sessions into an archive (see the module docstring).

    Args:
        client: the fleet client (its discovery watches the tokens).
        archive: the archive directory.
        options: how to run.
        log: receives one line per event (a session complete, acknowledged, an error).

    Raises:
        StorageError: another collector runs on the archive, or it cannot be created.
    """

    def __init__(
        self,
        client: FleetClient,
        archive: Path,
        options: CollectOptions | None = None,
        log: Callable[[str], None] = lambda _: None,
    ) -> None:
        self.client = client
        self.archive = archive
        self.options = options or CollectOptions()
        self.log = log
        self.total_limit = RateLimit(self.options.max_total_rate)
        self.report = CollectReport()
        self._lock = ArchiveLock(archive)
        self._places: dict[str, ArchivePlace] = {}
        self._places_lock = threading.Lock()
        self._workers: dict[str, VehicleWorker] = {}
        self._report_lock = threading.Lock()
        self._up: set[str] = set()

    # -- shared state

    def place(self, name: str) -> ArchivePlace:
        """Return the archive directory of a vehicle, its record loaded."""
        with self._places_lock:
            found = self._places.get(name)
            if found is None:
                found = self._places[name] = ArchivePlace(self.archive / name, self.log)
            return found

    def is_up(self, vehicle: str) -> bool:
        """Whether the vehicle's token is up now."""
        return vehicle in self.client.discovery.current()

    def count(self, place: ArchivePlace, amount: int) -> None:
        """Count bytes received from a vehicle."""
        with place.lock:
            place.record.received += amount
        with self._report_lock:
            self.report.received += amount

    def note_error(self, vehicle: str, error: str | None) -> None:
        """Keep (and log) a vehicle's last error; None clears it."""
        place = self.place(vehicle)
        with place.lock:
            if place.record.error != error:
                place.record.error = error
                place.dirty = True
        if error is not None:
            self.log(f"{vehicle}: {error}")

    def completed(self, place: str, outcome: FetchOutcome, state: str) -> None:
        """Report a session complete (or cut) on shore."""
        size = sum(f.size for f in outcome.files)
        what = "cut (its recorder died with it open)" if state == CUT else "complete"
        self.log(f"{place}: {outcome.session} {what}: {len(outcome.files)} file(s), {size} bytes")
        with self._report_lock:
            self.report.completed.append(f"{place}/{outcome.session}")

    def acked(self, place: str, session: str) -> None:
        """Report a session acknowledged by its vehicle."""
        self.log(f"{place}: {session} acknowledged by the vehicle")
        with self._report_lock:
            self.report.acked.append(f"{place}/{session}")

    def pruned(self, place: str, names: list[str], did: str) -> None:
        """Report sessions the vehicle's retention deleted."""
        self.log(f"{place}: the vehicle {did}")
        with self._report_lock:
            self.report.pruned.extend(f"{place}/{n}" for n in names)

    # -- running

    def _start(self, vehicle: str) -> None:
        worker = self._workers.get(vehicle)
        if worker is not None and worker.alive():
            return
        try:
            check_vehicle_dir(vehicle)
        except FormatError as err:
            if vehicle not in self.report.failed:
                self.report.failed[vehicle] = f"cannot be archived: {err}"
                self.log(f"{vehicle!r}: cannot be archived: {err}")
            return
        worker = VehicleWorker(self, vehicle)
        self._workers[vehicle] = worker
        worker.thread.start()

    def _watch(self) -> None:
        """Note who is up (their records say when each was last seen); start workers."""
        now = time.time()
        up = set(self.client.discovery.current())
        for vehicle in up:
            with contextlib.suppress(FormatError):
                place = self.place(check_vehicle_dir(vehicle))
                with place.lock:
                    place.record.seen = now
                    if not place.record.up:
                        place.record.up = True
                        place.dirty = True
        for vehicle in self._up - up:
            with contextlib.suppress(FormatError):
                place = self.place(check_vehicle_dir(vehicle))
                with place.lock:
                    place.record.up = False
                    place.dirty = True
            self.log(f"{vehicle}: its link is down (token gone)")
        for vehicle in up - self._up:
            self.log(f"{vehicle}: up; collecting")
            worker = self._workers.get(vehicle)
            if worker is not None:
                worker.wake.set()  # its link is back: retry now, not after the backoff
        self._up = up

    def _save(self, force: bool = False) -> None:
        with self._places_lock:
            places = list(self._places.values())
        for place in places:
            # a transfer's progress changes without marking the record: saved while in flight
            if place.dirty or force or place.record.in_flight:
                try:
                    place.save()
                except StorageError as err:
                    self.log(str(err))

    def run(
        self, stop: threading.Event | None = None, tick: Callable[[], None] = lambda: None
    ) -> CollectReport:
        """Collect until ``stop`` is set (or, with ``once``, until every vehicle up is done).

        Args:
            stop: set it to stop (the transfers keep their ``.part`` files).
            tick: called every half second while the collector is healthy (systemd's
                watchdog).

        Raises:
            StorageError: the archive's records cannot be written.
        """
        stop = stop or threading.Event()
        try:
            if self.options.once:
                return self._once(stop)
            last_save = 0.0
            while not stop.is_set():
                self._watch()
                for vehicle in self._up:
                    self._start(vehicle)
                if time.monotonic() - last_save >= _SAVE_EVERY:
                    self._save()
                    last_save = time.monotonic()
                tick()
                stop.wait(_TICK)
            return self.report
        finally:
            self._shutdown()

    def _once(self, stop: threading.Event) -> CollectReport:
        view = self.client.discover(self.options.expect)
        self.report.missing = view.missing
        if not view.vehicles and not view.missing:
            msg = (
                "no vehicle is up (no recorder or serve token answered; check --connect /"
                f" --mode){self.client.nobody_hint()}"
            )
            raise QueryError(msg)
        self._watch()
        for vehicle in view.names:
            self._start(vehicle)
        while any(w.alive() for w in self._workers.values()) and not stop.is_set():
            stop.wait(_TICK)
            self._save()
        for vehicle, worker in self._workers.items():
            if worker.error is not None:
                self.report.failed[vehicle] = worker.error
            elif worker.rounds == 0:
                self.report.failed[vehicle] = "interrupted"
        with self._places_lock:
            places = list(self._places.values())
        for place in places:
            with place.lock:
                for name, entry in place.record.sessions.items():
                    if entry.on_vehicle and not entry.done:
                        self.report.pending.append(f"{place.directory.name}/{name}")
        return self.report

    def _shutdown(self) -> None:
        for worker in self._workers.values():
            worker.stop()
        for worker in self._workers.values():
            worker.join(30.0)
        with self._places_lock:
            places = list(self._places.values())
        for place in places:
            with place.lock:
                place.record.in_flight.clear()
                place.record.up = False
        self._save(force=True)
        self._lock.release()
