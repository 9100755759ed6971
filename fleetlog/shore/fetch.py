"""Fetching a vehicle's session: resumable, verified, parallel ranges, optionally following.

:func:`fetch_session` downloads every file of a session into ``<out>/<session>/`` (the layout
pLogger writes), each through a :class:`~fleetlog.storage.download.PartFile`:

* ranges of 1 MiB, 8 in flight (measured here on a loaded 2-core machine: 4 in flight gave
  about 240 MB/s, 8 about 400 MB/s, 16 no more; 2 and 4 MiB ranges cost the vehicle less CPU
  per byte but touch more fresh memory on both sides, and were slower, docs/bench.md),
  appended in order so the ``.part`` length is always what arrived;
* a resumed or followed file is checked first: the range that continues it starts 4 KiB
  early, and those bytes must equal the end of the ``.part`` (a vehicle that rewrote the file,
  as pLogger does with ``FileTimeStamp = false``, is caught and the file fetched again);
* a complete file is verified against the vehicle's sha256, computed by the vehicle from the
  bytes it reads from its disk (asked for once the bytes are here: the vehicle hashes the
  ranges as it serves them, so the digest is ready without reading the file again; a resumed
  file's is asked for at the start), and only then renamed to its real name;
* a file of a session still being written stays a ``.part``: without ``follow`` the fetch
  takes what exists and returns; with ``follow`` it keeps fetching what is appended until the
  session ends (its metadata says ``closed``, or ``cut`` when its recorder died with it open;
  a session without metadata, real pLogger's, when the vehicle calls it complete), then
  verifies and renames. A recorder that stops stops serving: run ``fleetlog serve
  --standby`` beside it and the follow rides out the handover and ends verified;
* when the vehicle stops answering (link dropped, vehicle stopped) the range is retried with
  backoff for ``retry_for`` seconds; after that the fetch fails with the ``.part`` files in
  place, and the same command resumes them.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import QueryError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.pacing import FixedPacer, Pacer, RateLimit
from fleetlog.shore.transfer import FileOutcome, FileTransfer, Progress, TransferContext, riding_out
from fleetlog.storage.reserve import DEFAULT_SHORE_RESERVE, DiskReserve
from fleetlog.wire.query import DEFAULT_RANGE, SessionInfo, check_component
from fleetlog.wire.session_meta import CLOSED, CUT

__all__ = ["FetchOutcome", "fetch_session"]

WINDOW = 8
POLL = 1.0
RETRY_FOR = 30.0
#: names a vehicle never lists (a download in progress); one that does is not followed there
_DOWNLOADING = (".part", ".part.json", ".part.json.tmp")


@dataclass
class FetchOutcome:
    """What a session fetch did.

    Attributes:
        vehicle: the vehicle.
        session: the session.
        directory: where its files are.
        complete: the session was complete on the vehicle when the fetch ended.
        state: its metadata's state then (``open``, ``closed``, ``cut``), None without.
        received: bytes received over the network.
        seconds: how long it took.
        files: each file's outcome.
    """

    vehicle: str
    session: str
    directory: Path
    complete: bool = False
    state: str | None = None
    received: int = 0
    seconds: float = 0.0
    files: list[FileOutcome] = field(default_factory=list)


def _ended(info: SessionInfo) -> bool:
    """Whether a session is no longer written: marked closed or cut, or complete."""
    return info.complete or info.state in (CLOSED, CUT)


def fetch_session(
    client: FleetClient,
    vehicle: str,
    session: str,
    out_dir: Path,
    *,
    follow: bool = False,
    progress: Progress | None = None,
    window: int = WINDOW,
    chunk: int = DEFAULT_RANGE,
    poll: float = POLL,
    retry_for: float = RETRY_FOR,
    max_rate: float | None = None,
    cancel: threading.Event | None = None,
    server: str | None = None,
    pacer: Pacer | None = None,
    limits: Sequence[RateLimit] = (),
    names: Collection[str] | None = None,
    min_free: int = DEFAULT_SHORE_RESERVE,
) -> FetchOutcome:
    """Download a session of a vehicle into ``out_dir/<session>/``.

    Args:
        client: the fleet client.
        vehicle: the vehicle.
        session: the session's name.
        out_dir: where the session directory goes.
        follow: keep fetching a session that is being written until it completes.
        progress: receives byte counts.
        window: ranges in flight.
        chunk: bytes per range.
        poll: seconds between looks at a followed session.
        retry_for: seconds to keep retrying a vehicle that stopped answering.
        max_rate: bytes per second at most (a thin radio link), or None.
        cancel: set it to stop the fetch; the ``.part`` files stay.
        server: ask only the process with this Zenoh id (one of two recorders of the vehicle).
        pacer: decides the ranges in flight and their size (default: ``window`` ranges of
            ``chunk`` bytes); :class:`~fleetlog.shore.pacing.LinkPacer` for a shared radio
            link.
        limits: rate caps shared with other transfers (per vehicle, over the fleet).
        names: fetch only these files of the session (default: every file). Files go
            smallest first, so a session's ylog, slog, mission copy and metadata arrive
            before its alog.
        min_free: bytes to leave free on the file system of ``out_dir`` (0: no check); a
            file that would go below is not fetched (StorageError, the rest kept).

    Returns:
        What was fetched.

    Raises:
        QueryError: the vehicle refused a request, or stopped answering for ``retry_for``
            seconds; the files fetched so far are kept for the next run.
        StorageError: the local files cannot be written, or the disk is down to
            ``min_free``.
    """
    check_component(session, "session")
    started = time.monotonic()
    outcome = FetchOutcome(vehicle, session, out_dir / session)
    ctx = TransferContext(
        client,
        vehicle,
        session,
        progress or Progress(),
        pacer or FixedPacer(window, chunk),
        retry_for,
        (*limits, RateLimit(max_rate)) if max_rate else tuple(limits),
        cancel or threading.Event(),
        server,
        reserve=DiskReserve(out_dir, min_free) if min_free > 0 else None,
    )
    transfers: dict[str, FileTransfer] = {}
    try:
        while True:
            # Following: a vehicle that stops answering between two looks is retried too.
            info = riding_out(
                ctx, lambda: client.session(vehicle, session, brief=True, server=server)
            )
            wanted = [
                f
                for f in info.files
                if (names is None or f.name in names) and not f.name.endswith(_DOWNLOADING)
            ]
            ctx.progress.total(vehicle, sum(f.size for f in wanted))
            outcome.state = info.state
            for remote in sorted(wanted, key=lambda f: (f.size, f.name)):
                transfer = transfers.get(remote.name)
                if transfer is None:
                    transfer = FileTransfer(ctx, remote, outcome.directory / remote.name)
                    transfers[remote.name] = transfer
                    transfer.prepare(remote, info.complete)
                transfer.pull(remote.size)
            if _ended(info):
                for transfer in transfers.values():
                    transfer.ask_digest()  # every file's at once: one round trip, not one each
                for transfer in transfers.values():
                    transfer.finish()
                outcome.complete = True
                break
            if not follow:
                for transfer in transfers.values():
                    transfer.keep()
                break
            for transfer in transfers.values():
                transfer.recheck()  # a followed file is checked against the vehicle's each poll
            if ctx.cancel.wait(poll):
                msg = "the fetch was interrupted; the same command resumes it"
                raise QueryError(msg)
    finally:
        for transfer in transfers.values():
            transfer.abandon()
        outcome.received = ctx.received
        outcome.seconds = time.monotonic() - started
        outcome.files = [t.outcome() for t in transfers.values()]
    return outcome
