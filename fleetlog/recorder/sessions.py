"""The recorder's sessions: opening and closing them, fsync and gaps.

:class:`SessionKeeping` is the half of :class:`~fleetlog.recorder.engine.Recorder` that owns
the open :class:`~fleetlog.storage.session.SessionWriter`: the first session (after marking
the sessions a dead recorder left open as cut), LOGGER_RESTART, clean close and each
session's first and last metadata, the background fsync and the losses marked in the alog
(``PLOGGER_GAP``, docs/compat.md). Its bases: keeping the open session's metadata current,
:mod:`fleetlog.recorder.metadata`; what happens when the disk fails,
:mod:`fleetlog.recorder.faults`. The other half, what to log and how, is in
:mod:`fleetlog.recorder.engine`.

Its state lives in small groups (:class:`~fleetlog.recorder.faults.Health`,
:class:`~fleetlog.recorder.metadata.MetaState`) rather than on the Recorder: CPython keeps at
most 30 attributes of an object inline, and the hot path reads the Recorder's
(docs/reliability.md).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import uuid
from pathlib import Path
from typing import Any

from fleetlog import __version__
from fleetlog.errors import StorageError
from fleetlog.moos.alog import LineFormatter, Variant
from fleetlog.moos.mission import LoggerConfig
from fleetlog.moos.slog import SlogTable, SlotPatch
from fleetlog.recorder.clocksync import clock_state
from fleetlog.recorder.faults import RETRY_FIRST
from fleetlog.recorder.losses import reason_of
from fleetlog.recorder.metadata import MetadataKeeping
from fleetlog.storage.metafile import mark_cut_sessions
from fleetlog.storage.session import SessionLayout, SessionWriter
from fleetlog.wire.control import Outcome
from fleetlog.wire.session_meta import CLOSED, MAX_GAPS, OPEN, Gap, SessionMeta

__all__ = ["GAP_INTERVAL", "SessionKeeping"]

#: losses that did not break the session (DROP publishers', unreadable keys) are marked in
#: the alog at most this often
GAP_INTERVAL = 1.0


class SessionKeeping(MetadataKeeping):
    """The session half of the Recorder (a mixin: the Recorder sets what it uses)."""

    # What it uses of the Recorder (set by Recorder.__init__).
    config: LoggerConfig
    synclog: SlogTable | None
    app_name: str
    vehicle: str
    mission_path: Path | None
    _cwd: Path
    _fmt: LineFormatter

    def post(self, name: str, value: float | str) -> None:
        """Publish a message as pLogger (the Recorder's)."""
        raise NotImplementedError

    def status_text(self, now: float) -> str:
        """Return the PLOGGER_STATUS text (the Recorder's)."""
        raise NotImplementedError

    def flush(self) -> None:
        """Hand what was written to the OS (the Recorder's)."""
        raise NotImplementedError

    def _write_slog(self, text: str, patch: SlotPatch | None = None) -> None:
        raise NotImplementedError

    def _identity(self, now: float) -> dict[str, Any]:
        """Return a new session's ``mission_id``, ``part`` (and notes, tags): see modes.py."""
        return {"mission_id": uuid.uuid4().hex, "part": 1}

    @property
    def broken(self) -> str | None:
        """Why no session is open after a failure (None while writing works)."""
        return self._h.broken

    @property
    def synced_at(self) -> float | None:
        """When the open session's files were last fsynced (epoch)."""
        return self._h.synced_at

    @property
    def queue(self) -> int | None:
        """Samples the transport may hold before the recorder takes them."""
        return self._h.queue

    @queue.setter
    def queue(self, value: int | None) -> None:
        self._h.queue = value

    # ---------------------------------------------------------------------------------------
    # Sessions

    def layout(self) -> SessionLayout:
        """Return the session layout the configuration describes."""
        cfg = self.config
        return SessionLayout(
            file=cfg.file,
            path=cfg.path,
            timestamp=cfg.file_timestamp,
            utc=cfg.utc_log_directories,
            variant=Variant.EM if cfg.variant == "em" else Variant.IVP,
            compression=cfg.compress_alogs,
            sync_log=cfg.sync_log,
            exclusion_log=cfg.wildcard_exclusion_log,
            mark_data_type=cfg.mark_data_type,
            summary_file=cfg.logging_directory_summary_file,
            mission_path=self.mission_path,
            helm_task_file=cfg.helm_task_file,
        )

    @property
    def log_root(self) -> Path:
        """The directory the sessions are created in (pLogger's ``Path``)."""
        path = Path(self.config.path)
        return path if path.is_absolute() else self._cwd / path

    def current_session_name(self) -> str | None:
        """Return the open session's directory name (any thread)."""
        session = self.session
        return session.root if session is not None else None

    def start(self) -> SessionWriter | None:
        """Mark the sessions a dead recorder left open as cut, open the first session.

        Raises:
            StorageError: no session directory could be created at all.
        """
        self._m.cut_sessions = mark_cut_sessions(self.log_root, self._clock())
        session = self._open_session()
        for cut in self._m.cut_sessions:
            # A crash's gap is the first entry of the next session.
            self.gap(Gap(self._clock(), "crash", None, cut.updated, self.logstart, {}, cut.session))
        if self._m.cut_sessions:
            self.flush()  # the mark reaches the OS now, not with the first sample
        return session

    def _open_session(self, path: str | None = None) -> SessionWriter:
        now = self._clock()
        layout = self.layout()
        if path is not None:
            layout = dataclasses.replace(layout, path=path)
        session = SessionWriter.open(layout, self.logstart, when=now, cwd=self._cwd)
        self.session = session
        self._m.changed.set()
        self._h.in_fallback = path is not None
        self._unflushed_since = None
        self.stats.sessions += 1
        self._m.counters_at_open = self._counters()
        self._m.meta = SessionMeta(
            state=OPEN,
            vehicle=self.vehicle,
            session=session.root,
            recorder=self._m.recorder_id,
            fleetlog=__version__,
            opened=now,
            logstart=self.logstart,
            updated=now,
            counters=self._session_counters(),
            clock=clock_state(now),
            host=self._m.host,
            pid=os.getpid(),
            boot=self._m.boot,
            **self._identity(now),
        )
        # Visible at once (without waiting for the disk), so the session is never without
        # its state; made durable by the background writer right after.
        try:
            session.write_meta(self._m.meta.to_bytes(), durable=False)
        except StorageError as err:
            self._background_failed(err)
        self._write_meta(session, self._m.meta)
        self._h.broken = None
        self._h.retry_wait = RETRY_FIRST
        self._h.sync_due = now + self.config.fsync_interval
        self._h.unsynced = True  # its headers
        if session.fallback:
            self.debug(
                f"could not create {self.config.path}/{session.root}: "
                f"logging to the fallback {session.directory}"
            )
        for warning in session.warnings:
            self.debug(warning)
        if self.synclog is not None and session.slog is not None:
            text = self.synclog.start(session.banner(".slog", now), now - self.logstart)
            self._write_slog(text)
        self.post("LOGGER_DIRECTORY", session.directory)
        # Posted at once (not only every 2 s): its Community field names the vehicle in a
        # session that has no mission copy and no MOOSDB's DB_TIME (replay, serve read it).
        self.post(self.app_name.upper() + "_STATUS", self.status_text(now))
        # What was lost while no session was open is this session's first entries.
        self._write_gaps(now)
        return session

    def restart(self) -> Outcome:
        """Close the current session and open a new one (LOGGER_RESTART, §6.3 with §12's fixes).

        Every file is reopened (xlog and blog too), LOGSTART starts afresh, and a
        time-stamped directory is never reused.
        """
        # The fresh LOGSTART is taken first: the Closing notice comes back after the new
        # session opened, and a stamp before LOGSTART would count it as skewed.
        self.logstart = self._clock()
        old = self.session
        if old is not None:
            self.debug(f"Closing : {Path(old.directory).name}")
            self._close_session()
        new: SessionWriter | None
        try:
            new = self._open_session()
        except StorageError as err:
            self._storage_failed(err, lost=0)
            new = self._open_fallback()
            if new is None:
                self._set_broken(reason_of(err), self._clock())
        if new is not None:
            self.debug(f"Now Logging to : {Path(new.directory).name}")
            return Outcome.done(
                "restart", f"started session {new.root}", session=new.root, directory=new.directory
            )
        return Outcome.refused("restart", f"no session could be opened: {self.stats.last_error}")

    def _close_session(self) -> None:
        session = self.session
        if session is None:
            return
        self._unflushed_since = None
        try:
            session.close()
        except StorageError as err:
            # What close could not write is lost; the session is dropped either way.
            self.session = None
            self._count_unwritten(session, reason_of(err), self._clock())
            self._storage_failed(err, lost=0, fallback=False)
        self.session = None
        self._finish(session)

    def _finish(self, session: SessionWriter) -> None:
        """Sync a closed session's files and write its last metadata, off this thread."""
        self._m.changed.set()
        meta = self._m.meta
        self._m.meta = None
        final = None
        if meta is not None:
            final = dataclasses.replace(meta, counters=self._session_counters()).with_state(
                CLOSED, self._clock()
            )

        def finish() -> None:
            try:
                session.finish(final)
            except StorageError as err:
                self._background_failed(err)

        if session.layout.timestamp:
            self._background(finish)
        else:
            finish()  # the next session reuses the directory: its lock must be free first

    def stop(self) -> None:
        """Flush and close everything (clean shutdown)."""
        self._close_session()

    def gap(self, gap: Gap) -> None:
        """Mark a loss where it is noticed: a ``PLOGGER_GAP`` entry and a metadata gap."""
        session = self.session
        if session is None:
            return
        now = self._clock()
        offset = max(now - self.logstart, 0.0)
        line = self._fmt.string(offset, "PLOGGER_GAP", self.app_name, gap.moos_text())
        try:
            session.alog.write(line)
        except StorageError as err:
            self._storage_failed(err, lost=0)
            return
        if self._unflushed_since is None:
            self._unflushed_since = now
        meta = self._m.meta
        if meta is not None:
            gaps = meta.gaps if len(meta.gaps) < MAX_GAPS else meta.gaps[1:]
            self._update_meta(now, gaps=(*gaps, gap))

    def _write_gaps(self, now: float) -> None:
        self._h.gaps_at = now
        for gap in self.losses.take(now):
            self.gap(gap)

    def _sync(self, now: float) -> None:
        """Sync the open session's files in the background, one at a time (FsyncInterval)."""
        self._h.sync_due = now + self.config.fsync_interval
        session = self.session
        if session is None or self._h.sync_running:
            return
        self._h.sync_running = True
        # A compressed unit still open is synced once it has ended: it stays unsynced.
        self._h.unsynced = session.unit_due() is not None

        def sync() -> None:
            started = time.monotonic()
            try:
                session.sync()
            except StorageError as err:
                self._background_failed(err)
            else:
                self._h.synced_at = now
                self._h.max_fsync = max(self._h.max_fsync, time.monotonic() - started)
            finally:
                self._h.sync_running = False

        self._background(sync)

    def _session_tick(self, now: float) -> None:
        """The session's timers: retry after a failure, removal, gaps, fsync, metadata."""
        session = self.session
        if session is None:
            if self._h.broken is not None and now >= self._h.retry_at:
                self._retry(now)
        elif session.removed():
            # Noticed while idle too, before the next samples would go to unlinked files.
            self._session_removed(session, now)
        else:
            if self.losses and now - self._h.gaps_at >= GAP_INTERVAL:
                self._write_gaps(now)
            if (
                self.config.fsync_interval > 0
                and now >= self._h.sync_due
                and (self._h.unsynced or session.unit_due() is not None)
            ):
                self._sync(now)
        self._meta_tick(now)

    def _session_due(self, now: float) -> float:
        """Return when :meth:`_session_tick` next has work (epoch; inf: nothing timed).

        The directory's removal is checked at every tick, which comes at least every 2 s
        (PLOGGER_STATUS), and at every flush.
        """
        session = self.session
        if session is None:
            return self._h.retry_at if self._h.broken is not None else math.inf
        due = math.inf
        if self.losses:
            due = min(due, self._h.gaps_at + GAP_INTERVAL)
        if self.config.fsync_interval > 0 and self._h.unsynced:
            due = min(due, self._h.sync_due)
        unit = session.unit_due()
        if unit is not None:
            due = min(due, unit)
        meta = self._meta_due()
        if meta is not None:
            due = min(due, meta)
        return due

    def _end_lag_period(self) -> None:
        """A status period ends: its longest lag becomes the last period's."""
        session = self.session
        if session is not None:
            self._h.lag += session.take_wait()
        self._h.last_lag, self._h.lag = self._h.lag, 0.0

    def max_lag(self) -> float:
        """Return the longest a line waited from arrival to readable on disk, lately.

        Readable: handed to the OS (plain), in a complete unit (compressed: the arrival →
        flush and flush → unit maxima are added, an upper bound); over the last 2-4 s.
        """
        return max(self._h.lag, self._h.last_lag)
