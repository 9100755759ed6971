"""One file's download across polls, run per file by :func:`~fleetlog.shore.fetch.fetch_session`.

A :class:`FileTransfer` moves one vehicle file into its
:class:`~fleetlog.storage.download.PartFile`: ranges in flight sized by the measured link
rate, the overlap check of a resumed or followed ``.part`` (started over when the vehicle's
file no longer continues it), the vehicle's sha256 asked for and checked, then the rename.
:func:`riding_out` retries a call while the vehicle does not answer. :class:`Progress` and
:class:`FileOutcome` are what a fetch reports; the session-level loop (listing, polling,
following) is in :mod:`fleetlog.shore.fetch`.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from fleetlog.errors import QueryError, StorageError
from fleetlog.shore.answers import PendingRange, TransientQueryError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.pacing import Pacer, RateLimit
from fleetlog.storage.download import PartFile, sha256_file
from fleetlog.storage.reserve import DiskReserve
from fleetlog.wire.query import FileInfo, FileMeta

__all__ = [
    "OVERLAP",
    "FileOutcome",
    "FileTransfer",
    "Progress",
    "TransferContext",
    "riding_out",
]

OVERLAP = 4096


class Progress:
    """Receives a fetch's progress; the default does nothing. Must be thread-safe."""

    def total(self, vehicle: str, total: int) -> None:
        """The bytes the vehicle's session holds now."""

    def advance(self, vehicle: str, amount: int) -> None:
        """``amount`` more bytes are here (received, resumed, or already up to date)."""


@dataclass
class FileOutcome:
    """What happened to one file: ``fetched``, ``up to date`` or ``partial`` (.part kept).

    ``sha256`` is the vehicle's digest of the file, which the local copy was verified
    against (None unless fetched or up to date).
    """

    name: str
    size: int
    status: str
    sha256: str | None = None


_T = TypeVar("_T")


#: what a link is assumed to carry before one range has arrived (bytes/s): a slow radio
_FLOOR_RATE = 16_000.0
#: seconds of the link's measured rate kept in flight: enough to fill a fast link, few
#: enough on a radio that the last range asked arrives well within its timeout
_IN_FLIGHT_SECONDS = 4.0
#: a range's timeout beyond the time the bytes ahead of it need at the measured rate
_RANGE_SLACK = 15.0


class _LinkRate:
    """The rate ranges arrive at, so that a slow link gets fewer in flight and longer timeouts.

    Ranges asked back to back arrive one after another at the link's pace: a 1 MiB range
    takes 8 s at 1 Mbit/s, so eight asked at once with a fixed 10 s timeout time out on a
    radio however healthy it is.
    """

    def __init__(self) -> None:
        self.rate: float | None = None
        self._last: float | None = None

    def arrived(self, nbytes: int, busy_since: float) -> None:
        now = time.monotonic()
        start = busy_since if self._last is None else max(self._last, busy_since)
        self._last = now
        elapsed = now - start
        if elapsed <= 0 or nbytes <= 0:
            return
        sample = nbytes / elapsed
        self.rate = sample if self.rate is None else 0.7 * self.rate + 0.3 * sample

    def idle(self) -> None:
        self._last = None

    def window_bytes(self) -> float:
        return max(self.rate or 0.0, _FLOOR_RATE) * _IN_FLIGHT_SECONDS

    def timeout(self, bytes_ahead: int, base: float) -> float:
        return max(base, _RANGE_SLACK + bytes_ahead / max(self.rate or 0.0, _FLOOR_RATE))


@dataclass
class TransferContext:
    """What every file transfer of one session fetch shares: the vehicle, its link, limits."""

    client: FleetClient
    vehicle: str
    session: str
    progress: Progress
    pacer: Pacer
    retry_for: float
    limits: tuple[RateLimit, ...]
    cancel: threading.Event
    server: str | None = None
    received: int = 0
    link: _LinkRate = field(default_factory=_LinkRate)
    #: free space to leave where the files go (None: no check)
    reserve: DiskReserve | None = None


def riding_out(ctx: TransferContext, call: Callable[[], _T]) -> _T:
    """Call ``call``, retrying for ``retry_for`` seconds while the vehicle does not answer."""
    deadline = time.monotonic() + ctx.retry_for
    delay = 0.25
    while True:
        try:
            return call()
        except TransientQueryError as err:
            if time.monotonic() + delay > deadline or ctx.cancel.is_set():
                msg = f"{err} (the same command resumes the download of {ctx.session})"
                raise QueryError(msg) from None
            time.sleep(delay)
            delay = min(2.0, delay * 2)


class _Restart(Exception):
    """The vehicle's file no longer continues the ``.part``: start it over."""


class FileTransfer:
    """One file's download, across polls."""

    def __init__(self, ctx: TransferContext, remote: FileInfo, final: Path) -> None:
        self.ctx = ctx
        self.name = remote.name
        self.final = final
        source = {"vehicle": ctx.vehicle, "session": ctx.session, "file": remote.name}
        self.part = PartFile(final, source)
        self.status = ""
        self.meta: FileMeta | None = None
        self.sha256: str | None = None
        self._digest: PendingRange | None = None
        self._verify_tail = False

    # -- start

    def _ask_digest(self, size: int) -> PendingRange:
        # Hashing runs at roughly 1 GB/s; give large files the time they need.
        timeout = 60.0 + size / 20e6
        ctx = self.ctx
        return ctx.client.request_range(
            ctx.vehicle,
            ctx.session,
            self.name,
            0,
            0,
            sha256=True,
            timeout=timeout,
            server=ctx.server,
        )

    def prepare(self, remote: FileInfo, complete: bool) -> None:
        """Decide whether the file is already here, and open or resume its ``.part``."""
        ctx = self.ctx
        if (
            complete
            and self.final.is_file()
            and not self.part.part.exists()
            and self.final.stat().st_size == remote.size
        ):
            self._digest = self._ask_digest(remote.size)
            meta = self._digest_result()
            if meta.sha256 is not None and sha256_file(self.final) == meta.sha256:
                self.status = "up to date"
                self.sha256 = meta.sha256
                ctx.progress.advance(ctx.vehicle, remote.size)
                return
        resumed = self.part.open()
        # A fresh file's digest is asked for once its bytes are here (finish): the vehicle
        # hashes the ranges as it reads them, so by then it is known without a second read.
        # A resumed file's is asked for now, to know whether the .part is of this version;
        # the vehicle did not serve its start this time and hashes it meanwhile.
        if resumed and complete:
            self._digest = self._ask_digest(remote.size)
            meta = self._digest_result()
            if not self.part.remember(
                size=meta.size, mtime=meta.mtime, complete=True, sha256=meta.sha256
            ):
                self.part.reset()  # another version of the file than the one we began
                resumed = 0
            self._digest = self._ask_digest(meta.size)
        self._verify_tail = resumed > 0
        ctx.progress.advance(ctx.vehicle, resumed)

    def _digest_result(self) -> FileMeta:
        pending, self._digest = self._digest, None

        def attempt() -> FileMeta:
            nonlocal pending
            current = pending if pending is not None else self._ask_digest(self.part.size)
            pending = None  # a reply is read once; a retry asks again
            return current.result()[1]

        return self._retrying(attempt, "the sha256")

    # -- transfer

    def _retrying(self, call: Callable[[], FileMeta], what: str) -> FileMeta:
        deadline = time.monotonic() + self.ctx.retry_for
        delay = 0.25
        while True:
            try:
                return call()
            except TransientQueryError as err:
                if time.monotonic() + delay > deadline or self.ctx.cancel.is_set():
                    msg = (
                        f"{err} (while fetching {what} of {self.ctx.session}/{self.name};"
                        " the same command resumes the download)"
                    )
                    raise QueryError(msg) from None
                time.sleep(delay)
                delay = min(2.0, delay * 2)

    def pull(self, target: int) -> None:
        """Fetch until the ``.part`` holds ``target`` bytes (or what the file has, if less)."""
        if self.status:
            return
        if target == self.part.size > 0 and self.meta is not None:
            return  # nothing new (a followed file that did not grow): no range to ask
        if self.ctx.reserve is not None:
            # Refused before the first range: a file the disk cannot take (or a listing that
            # lies about its size) is not half-fetched into the reserve.
            what = f"{self.ctx.session}/{self.name}"
            self.ctx.reserve.check(max(0, target - self.part.size), what, writing=False)
        # retry_for counts from when the vehicle stopped answering, not from the start of the
        # file: a transfer longer than retry_for must still ride out a dropped link.
        deadline: float | None = None
        delay = 0.25
        restarts = 0
        while True:
            had = self.part.size
            try:
                self._pull(target)
                return
            except _Restart:
                restarts += 1
                if restarts > 3:
                    msg = f"{self.ctx.session}/{self.name} keeps changing on the vehicle"
                    raise QueryError(msg) from None
                self.part.reset()
            except TransientQueryError as err:
                if deadline is None or self.part.size > had:
                    deadline, delay = time.monotonic() + self.ctx.retry_for, 0.25
                if time.monotonic() + delay > deadline or self.ctx.cancel.is_set():
                    msg = (
                        f"{err} (at byte {self.part.size} of {self.ctx.session}/{self.name};"
                        " the same command resumes the download)"
                    )
                    raise QueryError(msg) from None
                time.sleep(delay)
                delay = min(2.0, delay * 2)
            else:  # pragma: no cover - _pull returns or raises
                return

    def _pull(self, target: int) -> None:
        ctx, part = self.ctx, self.part
        start = part.size
        overlap = min(OVERLAP, start) if self._verify_tail else 0
        cursor = start - overlap
        inflight: deque[tuple[PendingRange, float]] = deque()
        end = target
        link = ctx.link
        link.idle()
        asked_at = time.monotonic()
        while True:
            if ctx.cancel.is_set():
                msg = "the fetch was interrupted; the same command resumes it"
                raise QueryError(msg)
            ahead = sum(p.length for p, _ in inflight)
            while cursor < end and ctx.pacer.room(ahead, len(inflight)):
                if len(inflight) >= 2 and ahead >= link.window_bytes():
                    # As much in flight as the link carries in a few seconds, and never
                    # fewer than two ranges: between one range's end and the next one's
                    # first bytes the link would idle, and TCP restarts slowly after idling.
                    break
                length = min(ctx.pacer.chunk(), end - cursor)
                for limit in ctx.limits:
                    limit.wait(length)
                ahead += length
                timeout = link.timeout(ahead, ctx.client.timeout)
                request = ctx.client.request_range(
                    ctx.vehicle,
                    ctx.session,
                    self.name,
                    cursor,
                    length,
                    server=ctx.server,
                    timeout=timeout,
                )
                inflight.append((request, time.monotonic()))
                cursor += length
            if not inflight:
                return
            pending, sent = inflight.popleft()
            if pending.offset >= end:
                # Asked for before the file turned out shorter: nothing there to take.
                with contextlib.suppress(QueryError):
                    pending.result()
                continue
            try:
                data, meta = pending.result()
            except TransientQueryError:
                raise
            except QueryError:
                if self._remote_size() < pending.offset:
                    raise _Restart from None  # the file shrank: rewritten on the vehicle
                raise
            link.arrived(len(data), asked_at)
            ctx.pacer.arrived(len(data), time.monotonic() - sent)
            self.meta = meta
            if pending.offset + pending.length > meta.size:
                end = min(end, meta.size)  # the file is shorter than the listing said
            if pending.offset < part.size:
                seen = part.size - pending.offset
                if data[:seen] != part.tail(seen):
                    raise _Restart
                data = data[seen:]
                self._verify_tail = False
            if ctx.reserve is not None:
                ctx.reserve.check(len(data), f"{ctx.session}/{self.name}")
            part.append(data)
            ctx.received += len(data)
            ctx.progress.advance(ctx.vehicle, len(data))

    def _remote_size(self) -> int:
        ctx = self.ctx
        _, meta = ctx.client.read_range(
            ctx.vehicle, ctx.session, self.name, 0, 0, server=ctx.server
        )
        return meta.size

    def recheck(self) -> None:
        """Check the end of the ``.part`` against the vehicle's file on the next pull."""
        self._verify_tail = self.part.size > 0

    # -- end

    def ask_digest(self) -> None:
        """Ask for the file's sha256 now, without waiting (:meth:`finish` reads the answer)."""
        if not self.status and self._digest is None:
            self._digest = self._ask_digest(self.part.size)

    def finish(self) -> None:
        """The session is complete: fetch any rest, verify the sha256, rename."""
        if self.status:
            return
        meta = self._digest_result()
        if meta.sha256 is None:
            self.keep()  # not complete after all (the session was reopened?)
            return
        if self.part.size < meta.size:
            self.pull(meta.size)
        self.part.remember(size=meta.size, mtime=meta.mtime, complete=True, sha256=meta.sha256)
        if self.part.size != meta.size or self.part.digest() != meta.sha256:
            # What we hold is not the vehicle's file: fetch it once more from scratch.
            self.part.reset()
            self._verify_tail = False
            self.pull(meta.size)
        try:
            self.part.commit(meta.sha256)
        except StorageError as err:
            msg = f"vehicle {self.ctx.vehicle}: {err}"
            raise QueryError(msg) from None
        self.status = "fetched"
        self.sha256 = meta.sha256

    def keep(self) -> None:
        """Leave the ``.part`` for later (the session is still being written)."""
        if not self.status:
            self.part.close()
            self.status = "partial"

    def outcome(self) -> FileOutcome:
        """Return what happened to the file."""
        size = self.part.size
        if self.status == "up to date":
            size = self.final.stat().st_size
        return FileOutcome(self.name, size, self.status or "failed", self.sha256)

    def abandon(self) -> None:
        """Close the ``.part`` after a failure; it stays for the next run."""
        if not self.status:
            self.part.close()
