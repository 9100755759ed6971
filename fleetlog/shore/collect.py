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
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import FleetlogError, FormatError, QueryError, StorageError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.fetch import FetchOutcome, fetch_session
from fleetlog.shore.pacing import LinkPacer, RateLimit
from fleetlog.shore.transfer import Progress
from fleetlog.storage.archive import (
    COMPLETE,
    CUT,
    PARTIAL,
    ArchivedFile,
    ArchiveLock,
    VehicleRecord,
    check_vehicle_dir,
    load_record,
    save_record,
)
from fleetlog.storage.catalog import ALOG_SUFFIXES
from fleetlog.wire.query import SessionInfo, check_component
from fleetlog.wire.session_meta import CLOSED
from fleetlog.wire.session_meta import CUT as META_CUT

__all__ = ["CollectOptions", "CollectReport", "Collector", "plan_fetches", "pruned_names"]

#: how often the collector looks at the fleet's tokens and writes its records
_TICK = 0.5
_SAVE_EVERY = 2.0
#: sessions one prune reply may name (the vehicle names at most 1024)
MAX_PRUNED = 4096


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


def _ended(info: SessionInfo) -> bool:
    return info.complete or info.state in (CLOSED, META_CUT)


def _small(name: str) -> bool:
    return not name.endswith(ALOG_SUFFIXES)


def plan_fetches(todo: Iterable[SessionInfo]) -> list[tuple[SessionInfo, frozenset[str] | None]]:
    """Order the fetches of the ended sessions of a round (the one being recorded is followed).

    Newest first, in two passes: every session's small files (metadata, ylog, slog, mission
    copy...), then each session whole (its alog; the small files are then up to date).

    Args:
        todo: the sessions not all on shore, newest first.

    Returns:
        ``(session, names)`` in order: ``names`` the files of a first-pass fetch, None for a
        whole session.
    """
    ended = [info for info in todo if _ended(info)]
    first: list[tuple[SessionInfo, frozenset[str] | None]] = []
    for info in ended:
        small = frozenset(f.name for f in info.files if _small(f.name))
        if small and len(small) < len(info.files):
            first.append((info, small))
    return first + [(info, None) for info in ended]


def pruned_names(extra: Mapping[str, Any]) -> list[str]:
    """The sessions a ``prune`` reply says were removed (a vehicle's reply, read defensively)."""
    removed = extra.get("removed")
    if not isinstance(removed, list):
        return []
    return [n for n in removed[:MAX_PRUNED] if isinstance(n, str)]


class _Counter(Progress):
    """Keeps a transfer's figures in its in-flight entry (what ``--status`` shows)."""

    def __init__(self, flight: dict[str, Any], lock: threading.RLock) -> None:
        self._flight = flight
        self._lock = lock

    def total(self, vehicle: str, total: int) -> None:
        with self._lock:
            self._flight["size"] = total

    def advance(self, vehicle: str, amount: int) -> None:
        with self._lock:
            self._flight["here"] = self._flight.get("here", 0) + amount


class _Place:
    """One archive directory (a vehicle, or one of two processes answering for it)."""

    def __init__(self, directory: Path, log: Callable[[str], None]) -> None:
        self.directory = directory
        self.lock = threading.RLock()
        self.dirty = False
        try:
            record = load_record(directory)
        except (StorageError, FormatError) as err:
            log(f"{directory.name}: its archive record cannot be read ({err}); starting afresh")
            record = None
        self.record = record or VehicleRecord(directory.name)

    def save(self) -> None:
        with self.lock:
            self.record.updated = time.time()
            save_record(self.directory, self.record)
            self.dirty = False


class _Worker:
    """Collects one vehicle while its link answers (see the module docstring)."""

    def __init__(self, collector: Collector, vehicle: str) -> None:
        self.c = collector
        self.vehicle = vehicle
        opts = collector.options
        self.pacer = LinkPacer(target=opts.target_delay)
        self.limits = tuple(
            limit for limit in (RateLimit(opts.max_rate), collector.total_limit) if limit.rate
        )
        self.cancel = threading.Event()
        #: set when the vehicle's token comes up again: a worker waiting to retry goes on
        self.wake = threading.Event()
        #: (archive directory, session) being fetched now: never two fetches of one session
        self._busy: set[tuple[str, str]] = set()
        self._busy_lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, name=f"collect-{vehicle}", daemon=True)
        self.follower: threading.Thread | None = None
        self.following: tuple[str, str] | None = None  # (place, session)
        self.error: str | None = None
        self.rounds = 0
        self._ack_said: str | None = None

    # -- the loop

    def _run(self) -> None:
        c = self.c
        delay = 1.0
        while not self.cancel.is_set():
            try:
                self.round()
            except FleetlogError as err:
                if self.cancel.is_set():
                    return  # stopped: what is in flight stays for the next start, no error
                self.error = str(err)
                c.note_error(self.vehicle, str(err))
                if c.options.once or not c.is_up(self.vehicle):
                    return
                self._sleep(delay)
                delay = min(30.0, delay * 2)
                continue
            self.error = None
            c.note_error(self.vehicle, None)
            delay = 1.0
            self.rounds += 1
            if c.options.once:
                return
            self._sleep(c.options.rescan)

    def _sleep(self, seconds: float) -> None:
        self.wake.wait(seconds)
        self.wake.clear()

    def stop(self) -> None:
        self.cancel.set()
        self.wake.set()

    def alive(self) -> bool:
        return self.thread.is_alive() or (self.follower is not None and self.follower.is_alive())

    def join(self, timeout: float) -> None:
        self.thread.join(timeout)
        if self.follower is not None:
            self.follower.join(timeout)

    # -- one round

    def round(self) -> None:
        c = self.c
        by_server = c.client.sessions_by_server(self.vehicle, brief=True)
        conflict = len(by_server) > 1
        for zid, sessions in by_server.items():
            name = f"{self.vehicle}@{zid}" if conflict else self.vehicle
            place = c.place(check_vehicle_dir(name))
            server = zid if conflict else None
            self._sync(place, sessions, server)

    def _sync(self, place: _Place, sessions: list[SessionInfo], server: str | None) -> None:
        c = self.c
        with place.lock:
            record = place.record
            listed = {info.name for info in sessions}
            for info in sessions:
                try:
                    check_component(info.name, "session")
                except FormatError:
                    continue
                if info.name.startswith("."):
                    continue  # never a session (pLogger's are named MOOSLog_…): not archived
                entry = record.session(info.name)
                entry.remote = {f.name: f.size for f in info.files}
                # a verified file the vehicle now lists at another size is fetched again
                entry.files = {
                    n: f for n, f in entry.files.items() if entry.remote.get(n, f.size) == f.size
                }
                entry.on_vehicle = True
                entry.vehicle_state = info.state
                if entry.done and self._changed(entry.remote, entry.files):
                    # The vehicle's files differ from ours: fetch again, and acknowledge the
                    # new bytes (the old ack no longer matches what the vehicle holds).
                    entry.state = PARTIAL
                    entry.acked = None
            for name, entry in record.sessions.items():
                if name not in listed:
                    entry.on_vehicle = False
            place.dirty = True
            todo = [
                info
                for info in reversed(sessions)  # newest first
                if info.name in record.sessions and not record.sessions[info.name].done
            ]
        for info in todo:
            if not _ended(info):
                self._follow(place, info, server)
        for info, names in plan_fetches(todo):
            if names is not None:
                outcome = self._fetch(place, info.name, server, names=names, how="small files")
                if outcome is not None:
                    self._settle(place, outcome, partial=True)
                continue
            with place.lock:
                entry = place.record.session(info.name)
                # what the first pass verified is not asked about again
                rest = [f.name for f in info.files if f.name not in entry.files]
            outcome = self._fetch(place, info.name, server, names=rest, how="fetch")
            if outcome is not None:
                self._settle(place, outcome)
        self._acknowledge(place)
        if c.options.prune:
            self._prune(place)

    @staticmethod
    def _changed(remote: dict[str, int], files: dict[str, ArchivedFile]) -> bool:
        return any(files.get(n) is None or files[n].size != s for n, s in remote.items())

    # -- fetching

    def _fetch(
        self,
        place: _Place,
        session: str,
        server: str | None,
        *,
        names: Iterable[str] | None = None,
        how: str,
        follow: bool = False,
    ) -> FetchOutcome | None:
        c = self.c
        key = (place.directory.name, session)
        with self._busy_lock:
            if key in self._busy:
                return None  # the follower has it (it ended meanwhile): it finishes it
            self._busy.add(key)
        flight: dict[str, Any] = {"session": session, "how": how, "since": time.time()}
        with place.lock:
            place.record.in_flight.append(flight)
            place.dirty = True
        try:
            outcome = fetch_session(
                c.client,
                self.vehicle,
                session,
                place.directory,
                follow=follow,
                progress=_Counter(flight, place.lock),
                poll=c.options.poll,
                retry_for=c.options.retry_for,
                cancel=self.cancel,
                server=server,
                pacer=self.pacer,
                limits=self.limits,
                names=None if names is None else frozenset(names),
            )
        finally:
            with self._busy_lock:
                self._busy.discard(key)
            with place.lock:
                with contextlib.suppress(ValueError):
                    place.record.in_flight.remove(flight)
                place.dirty = True
        c.count(place, outcome.received)
        return outcome

    def _follow(self, place: _Place, info: SessionInfo, server: str | None) -> None:
        """Follow the session being recorded, in a thread of its own (one at a time)."""
        if self.c.options.once:
            # Once: take what exists now; it stays .part until a later run sees it end.
            outcome = self._fetch(place, info.name, server, how="fetch")
            if outcome is not None and outcome.complete:
                self._settle(place, outcome)
            return
        if self.follower is not None and self.follower.is_alive():
            return

        def follow() -> None:
            try:
                outcome = self._fetch(place, info.name, server, how="follow", follow=True)
                if outcome is not None:
                    self._settle(place, outcome)
                    self._acknowledge(place)
                    if self.c.options.prune:
                        self._prune(place)
            except FleetlogError as err:
                if not self.cancel.is_set():
                    self.c.note_error(self.vehicle, f"following {info.name}: {err}")
            finally:
                self.following = None

        self.following = (place.directory.name, info.name)
        self.follower = threading.Thread(
            target=follow, name=f"collect-follow-{self.vehicle}", daemon=True
        )
        self.follower.start()

    def _settle(self, place: _Place, outcome: FetchOutcome, *, partial: bool = False) -> None:
        """Keep the files verified; mark the session complete (or cut) once all of them are.

        ``partial``: the fetch was of some files only (the first pass).
        """
        verified = {
            f.name: ArchivedFile(f.size, f.sha256)
            for f in outcome.files
            if f.status in ("fetched", "up to date") and f.sha256 is not None
        }
        with place.lock:
            entry = place.record.session(outcome.session)
            entry.files.update(verified)
            if outcome.complete and not partial:
                # the vehicle's files as the fetch last listed them (a followed session's
                # metadata appears or changes while it is followed)
                entry.remote = {
                    **{n: s for n, s in entry.remote.items() if n in entry.files},
                    **{f.name: f.size for f in outcome.files},
                }
            complete = (
                outcome.complete
                and not partial
                and bool(entry.remote)
                and all(
                    n in entry.files and entry.files[n].size == s for n, s in entry.remote.items()
                )
            )
            if not complete:
                entry.state = PARTIAL
                place.dirty = True
                return
            entry.state = CUT if outcome.state == META_CUT else COMPLETE
            entry.vehicle_state = outcome.state
            entry.completed = time.time()
            place.dirty = True
            place.save()
        self.c.completed(place.directory.name, outcome, entry.state)

    # -- retention on the vehicle

    def _acknowledge(self, place: _Place) -> None:
        """Acknowledge every complete session the vehicle still holds and has not acked."""
        c = self.c
        with place.lock:
            todo = [
                (name, {n: f.sha256 for n, f in entry.files.items() if n in entry.remote})
                for name, entry in place.record.sessions.items()
                if entry.done and entry.on_vehicle and entry.acked is None and entry.remote
            ]
        for session, files in todo:
            request: dict[str, Any] = {
                "cmd": "ack",
                "session": session,
                "files": files,
                "source": c.options.source,
                "time": time.time(),
            }
            try:
                replies = c.client.control(self.vehicle, request)
            except QueryError as err:
                # No recorder answers (a vehicle served by `fleetlog serve` alone): the acks
                # wait for one; said once, not every round.
                said = f"sessions not acknowledged yet: {err}"
                if said != self._ack_said:
                    c.log(f"{self.vehicle}: {said}")
                    self._ack_said = said
                return
            self._ack_said = None
            if any(r.ok for r in replies):
                with place.lock:
                    place.record.session(session).acked = time.time()
                    place.dirty = True
                c.acked(place.directory.name, session)
            else:
                why = "; ".join(r.describe() for r in replies)
                c.log(f"{self.vehicle}: the vehicle did not acknowledge {session}: {why}")

    def _prune(self, place: _Place) -> None:
        c = self.c
        with place.lock:
            waiting = [
                n for n, e in place.record.sessions.items() if e.on_vehicle and e.acked is not None
            ]
        if not waiting:
            return
        try:
            replies = c.client.prune(self.vehicle, source=c.options.source)
        except QueryError as err:
            c.log(f"{self.vehicle}: prune not done: {err}")
            return
        for reply in replies:
            if not reply.ok:
                c.log(f"{self.vehicle}: {reply.describe()}")
                continue
            names = pruned_names(reply.extra)
            with place.lock:
                for name in names:
                    entry = place.record.sessions.get(name)
                    if entry is not None:
                        entry.on_vehicle = False
                        entry.pruned = time.time()
                place.dirty = True
            c.pruned(place.directory.name, names, reply.did)


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
        self._places: dict[str, _Place] = {}
        self._places_lock = threading.Lock()
        self._workers: dict[str, _Worker] = {}
        self._report_lock = threading.Lock()
        self._up: set[str] = set()

    # -- shared state

    def place(self, name: str) -> _Place:
        """Return the archive directory of a vehicle, its record loaded."""
        with self._places_lock:
            found = self._places.get(name)
            if found is None:
                found = self._places[name] = _Place(self.archive / name, self.log)
            return found

    def is_up(self, vehicle: str) -> bool:
        """Whether the vehicle's token is up now."""
        return vehicle in self.client.discovery.current()

    def count(self, place: _Place, amount: int) -> None:
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
        worker = _Worker(self, vehicle)
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
