"""One vehicle's collection rounds, run by :class:`~fleetlog.shore.collect.Collector`.

A :class:`VehicleWorker` collects one vehicle while its link answers: it lists the
vehicle's sessions, follows the one being recorded, fetches the others in the order of
:func:`plan_fetches`, settles each outcome in the archive's record (an :class:`ArchivePlace`),
acknowledges what is complete and, with ``prune``, asks the vehicle to delete it. The
fleet-level loop (tokens, one worker per vehicle, the report) stays in
:mod:`fleetlog.shore.collect`.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlog.errors import FleetlogError, FormatError, QueryError, StorageError
from fleetlog.shore.fetch import FetchOutcome, fetch_session
from fleetlog.shore.pacing import LinkPacer, RateLimit
from fleetlog.shore.transfer import Progress
from fleetlog.storage.archive import (
    COMPLETE,
    CUT,
    PARTIAL,
    ArchivedFile,
    VehicleRecord,
    check_vehicle_dir,
    load_record,
    save_record,
)
from fleetlog.storage.catalog import ALOG_SUFFIXES
from fleetlog.wire.query import SessionInfo, check_component
from fleetlog.wire.session_meta import CLOSED
from fleetlog.wire.session_meta import CUT as META_CUT

if TYPE_CHECKING:
    from fleetlog.shore.collect import Collector

__all__ = ["MAX_PRUNED", "ArchivePlace", "VehicleWorker", "plan_fetches", "pruned_names"]

#: sessions one prune reply may name (the vehicle names at most 1024)
MAX_PRUNED = 4096


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


class ArchivePlace:
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
        """Write the record to the archive directory."""
        with self.lock:
            self.record.updated = time.time()
            save_record(self.directory, self.record)
            self.dirty = False


class VehicleWorker:
    """Collects one vehicle while its link answers (the steps: :mod:`fleetlog.shore.collect`)."""

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
        """Ask the worker to stop (and wake it if it waits)."""
        self.cancel.set()
        self.wake.set()

    def alive(self) -> bool:
        """Whether the worker or its follower still runs."""
        return self.thread.is_alive() or (self.follower is not None and self.follower.is_alive())

    def join(self, timeout: float) -> None:
        """Wait for the worker and its follower to end."""
        self.thread.join(timeout)
        if self.follower is not None:
            self.follower.join(timeout)

    # -- one round

    def round(self) -> None:
        """Run one round over every process answering for the vehicle."""
        c = self.c
        by_server = c.client.sessions_by_server(self.vehicle, brief=True)
        conflict = len(by_server) > 1
        for zid, sessions in by_server.items():
            name = f"{self.vehicle}@{zid}" if conflict else self.vehicle
            place = c.place(check_vehicle_dir(name))
            server = zid if conflict else None
            self._sync(place, sessions, server)

    def _sync(self, place: ArchivePlace, sessions: list[SessionInfo], server: str | None) -> None:
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
        place: ArchivePlace,
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
                min_free=c.options.min_free,
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

    def _follow(self, place: ArchivePlace, info: SessionInfo, server: str | None) -> None:
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

    def _settle(self, place: ArchivePlace, outcome: FetchOutcome, *, partial: bool = False) -> None:
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

    def _acknowledge(self, place: ArchivePlace) -> None:
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

    def _prune(self, place: ArchivePlace) -> None:
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
