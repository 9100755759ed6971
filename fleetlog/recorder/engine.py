"""The pLogger engine: what to log where, throttles, commands, restart, monitor, timers.

The engine has no Zenoh in it: it takes MOOS messages (:meth:`Recorder.handle`), a clock and a
``publish`` function for what pLogger posts itself (MOOS_DEBUG, LOGGER_DIRECTORY,
PLOGGER_STATUS), which come back through the subscription and get logged as pLogger's own
posts come back through the MOOSDB. Its timing (throttles, slog rows, MONITOR) is therefore
tested with a fake clock and real files.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import stat
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog import __version__
from fleetlog.errors import FleetlogError, MissionError, RecorderError, StorageError
from fleetlog.moos.alog import LineFormatter, Variant, source_field
from fleetlog.moos.mission import LoggerConfig, LogSpec, parse_log_spec
from fleetlog.moos.naming import copy_file_name
from fleetlog.moos.patterns import Verdict, WildcardClassifier, name_to_chunk
from fleetlog.moos.slog import SlogTable, SlotPatch
from fleetlog.moos.ylog import format_ylog_line
from fleetlog.recorder.clocksync import clock_state
from fleetlog.recorder.control import (
    MAX_COPIES,
    MAX_COPY_BYTES,
    MAX_LOG_REQUESTS,
    MAX_VAR_NAME,
    CommandHandler,
    clip,
    quote,
)
from fleetlog.recorder.losses import LossLedger, reason_of
from fleetlog.storage.metafile import boot_id, host_name, mark_cut_sessions
from fleetlog.storage.procinfo import ProcessMonitor
from fleetlog.storage.session import SessionLayout, SessionWriter
from fleetlog.wire.control import Outcome
from fleetlog.wire.message import MoosMessage
from fleetlog.wire.session_meta import CLOSED, MAX_GAPS, OPEN, Gap, SessionMeta
from fleetlog.wire.version import WIRE_VERSION

__all__ = ["SKEW_TOLERANCE", "Recorder", "RecorderStats"]

#: pLogger's (MOOSMsg's) skew tolerance, seconds
SKEW_TOLERANCE = 5.0
#: MONITOR's check interval and tolerance, and LOGGER_DIRECTORY's republish interval
MONITOR_INTERVAL = 10.0
#: CMOOSApp's status period
STATUS_INTERVAL = 2.0
#: samples lost before reaching the recorder are reported on MOOS_DEBUG at most this often
MISSED_REPORT_INTERVAL = 1.0
_SYSTEM_VARS = ("MOOS_DEBUG", "MOOS_SYSTEM")

#: the session metadata is rewritten at most this often while counters change
META_INTERVAL = 2.0
#: losses that did not break the session (DROP publishers', unreadable keys) are marked in
#: the alog at most this often
GAP_INTERVAL = 1.0
#: with no session open, opening one is retried after this long (doubling up to the maximum)
RETRY_FIRST = 1.0
RETRY_MAX = 8.0
#: a file system with less free space than this is not worth a retry yet
MIN_FREE_BYTES = 1 << 20
#: notes one session may hold
MAX_NOTES = 64

Publish = Callable[[MoosMessage], None]
#: runs file work the drain thread must not wait for (fsync, metadata) in order, elsewhere
Background = Callable[[Callable[[], None]], None]


def _inline(job: Callable[[], None]) -> None:
    job()


@dataclass(slots=True)
class RecorderStats:
    """What the recorder did with what it received; nothing is lost without a count here."""

    received: int = 0
    logged: int = 0
    excluded: int = 0
    ignored: int = 0
    throttled: int = 0
    skewed: int = 0
    garbled: int = 0
    lost: int = 0
    #: samples that publishers with sample-miss detection (DROP) sent but never arrived;
    #: those of variables the recorder logs are also in ``lost``
    missed: int = 0
    #: samples whose type differs from their variable's first (MOOS keeps the first type;
    #: the recorder logs both)
    type_clashes: int = 0
    write_errors: int = 0
    refused_copies: int = 0
    sessions: int = 0
    #: commands received by any path (PLOGGER_CMD, LOGGER_RESTART, control), and refused
    commands: int = 0
    refused_commands: int = 0
    last_error: str = ""

    def as_dict(self) -> dict[str, int | str]:
        """Return the counters as a dict (for the status publication and query)."""
        # Never through ``__dict__``: reading an object's ``__dict__`` makes CPython keep its
        # attributes in a real dict from then on, and every ``stats.x += 1`` in the hot
        # path slower (measured: 0.1 µs a sample). Slots keep them fast.
        return {name: getattr(self, name) for name in _STAT_FIELDS}


_STAT_FIELDS = tuple(f.name for f in dataclasses.fields(RecorderStats))
_COUNTER_FIELDS = tuple(f.name for f in dataclasses.fields(RecorderStats) if f.type == "int")


@dataclass(slots=True)
class _Var:
    """Per-variable state, built once per name (the hot path reads only this)."""

    verdict: Verdict
    period: float
    system: bool
    last_logged: float = -1e300
    last_seen: float | None = None
    #: the type of the variable's first value (float, str or bytes)
    kind: type | None = None


@dataclass
class _Timers:
    monitor: float = 0.0
    status: float = 0.0
    missed: float = -1e300
    meta: float = 0.0
    #: when the last slog row was written
    last_row: float = -1e300


@dataclass
class _Health:
    """How writing goes: failures, retries, lag, fsync (cold state, kept off the Recorder).

    The Recorder itself keeps at most 30 attributes: CPython 3.11 keeps an instance's
    attributes inline (fast ``self.x`` in the hot path) only up to that many; past it every
    attribute read in :meth:`Recorder.handle` got 15 % slower (measured, docs/reliability.md).
    """

    #: why no session is open after a failure (None while writing works)
    broken: str | None = None
    retry_at: float = 0.0
    retry_wait: float = 1.0
    #: the longest a line waited between arrival and the OS, this status period and the last
    lag: float = 0.0
    last_lag: float = 0.0
    #: fsync: when the last one finished (epoch), the longest it took, the next, one running
    synced_at: float | None = None
    max_fsync: float = 0.0
    sync_due: float = 0.0
    sync_running: bool = False
    #: when losses were last marked in the alog
    gaps_at: float = 0.0
    #: samples the transport may hold before the recorder takes them (set by the service)
    queue: int | None = None
    #: the open session is the recorder's own fallback after a write error
    in_fallback: bool = False
    #: keys already reported as naming no variable
    unreadable: set[str] = field(default_factory=set)
    #: samples lost on the way per publisher (its Zenoh id), not yet on MOOS_DEBUG
    missed: dict[str, int] = field(default_factory=dict)


@dataclass
class _CommandLimits:
    """What LOG_REQUEST and COPY_FILE_REQUEST have used of their bounds (issue 10)."""

    #: variables added by LOG_REQUEST so far (at most MAX_LOG_REQUESTS)
    requested: int = 0
    #: copies made by COPY_FILE_REQUEST into the session they were made in
    copy_session: SessionWriter | None = None
    copies: int = 0


@dataclass
class _AppStatus:
    """What CMOOSApp's status says beyond the counters: CPU and memory, posts, subscriptions."""

    proc: ProcessMonitor = field(default_factory=ProcessMonitor)
    published: set[str] = field(default_factory=set)
    subscribed: set[str] = field(default_factory=set)


@dataclass
class _MetaState:
    """The open session's metadata and what it is built from."""

    recorder_id: str
    host: str
    boot: str
    meta: SessionMeta | None = None
    counters_at_open: dict[str, int] = field(default_factory=dict)
    meta_counters: dict[str, int] = field(default_factory=dict)
    #: sessions found cut at start, marked by the first session's first entries
    cut_sessions: list[SessionMeta] = field(default_factory=list)


class Recorder:
    """One vehicle's pLogger: sessions on disk from a stream of MOOS messages.

    Args:
        config: the pLogger configuration (mission block, or the defaults).
        vehicle: the vehicle (MOOS community) recorded; the recorder's own posts use it.
        publish: sends a message the recorder posts itself (MOOS_DEBUG, LOGGER_DIRECTORY, …).
        mission_path: the mission file (backed up as ``._moos``), if any.
        cwd: where relative paths start (the process's cwd by default).
        copy_dirs: directories COPY_FILE_REQUEST may read from (resolved).
        clock: the wall clock, seconds since the epoch.
        subscribe: asks the transport to deliver a variable added by LOG_REQUEST.
        recorder_id: this recorder's Zenoh id (for the session metadata).
        background: runs fsync and metadata writes off the recording thread (inline by
            default, for tests).
    """

    def __init__(
        self,
        config: LoggerConfig,
        *,
        vehicle: str,
        publish: Publish,
        mission_path: Path | None = None,
        cwd: Path | None = None,
        copy_dirs: Sequence[Path] = (),
        clock: Callable[[], float] = time.time,
        subscribe: Callable[[str], None] | None = None,
        recorder_id: str = "",
        background: Background = _inline,
    ) -> None:
        self.config = config
        self._background = background
        self.vehicle = vehicle
        self._publish = publish
        self._clock = clock
        self._subscribe = subscribe
        self._cwd = Path.cwd() if cwd is None else cwd
        self.mission_path = mission_path
        self.copy_dirs = tuple(p.resolve() for p in copy_dirs)
        self.app_name = config.app_name
        self.stats = RecorderStats()
        #: LOGSTART: taken at construction, before Zenoh connects, as CMOOSApp does
        self.logstart = clock()
        self.started = self.logstart
        variant = Variant.EM if config.variant == "em" else Variant.IVP
        self._fmt = LineFormatter(
            variant, config.double_precision, mark_data_type=config.mark_data_type
        )
        specs: dict[str, LogSpec] = {}
        for spec in config.log_specs:
            specs.setdefault(spec.var, spec)
        self._specs = specs
        self._classifier = WildcardClassifier(
            log_vars=list(specs),
            patterns=config.wildcard_patterns,
            omit_patterns=config.wildcard_omit_patterns,
            exclusion_log=config.wildcard_exclusion_log,
            wildcard_enabled=config.wildcard_logging,
        )
        self._vars: dict[str, _Var] = {}
        self._sources: dict[tuple[str, str, str], str] = {}
        self.commands = CommandHandler(self, clock)
        #: the two command variables (LOGGER_RESTART, <APP>_CMD)
        self._cmd_names = frozenset((self.commands.restart_var, self.commands.command_var))
        self.monitored = [s.var for s in specs.values() if s.monitor]
        sync_columns = [s.var for s in specs.values() if s.sync]
        self.synclog = (
            SlogTable(sync_columns, config.dynamic_sync_log_columns) if config.sync_log else None
        )
        self._timers = _Timers(monitor=self.logstart, status=self.logstart)
        self.session: SessionWriter | None = None
        self._unflushed_since: float | None = None
        #: what LOG_REQUEST and COPY_FILE_REQUEST have used of their bounds
        self._limits = _CommandLimits()
        #: CMOOSApp's status fields: CPU and memory, what it posts, what it receives
        self._app = _AppStatus()
        #: losses not yet marked in a log (docs/compat.md, PLOGGER_GAP)
        self.losses = LossLedger()
        self._h = _Health()
        self._m = _MetaState(recorder_id, host_name(), boot_id())
        # Keep the attributes above at 30 or fewer (see _Health): new state goes in a group.

    @property
    def broken(self) -> str | None:
        """Why no session is open after a failure (None while writing works)."""
        return self._h.broken

    @property
    def synced_at(self) -> float | None:
        """When the open session's files were last fsynced (epoch)."""
        return self._h.synced_at

    @property
    def meta(self) -> SessionMeta | None:
        """The open session's metadata."""
        return self._m.meta

    @property
    def cut_sessions(self) -> list[SessionMeta]:
        """The sessions found cut when the recorder started."""
        return self._m.cut_sessions

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

    def start(self) -> SessionWriter:
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
            mission_id=uuid.uuid4().hex,
            part=1,
            counters=self._session_counters(),
            clock=clock_state(now),
            host=self._m.host,
            pid=os.getpid(),
            boot=self._m.boot,
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

    def subscription_chunks(self) -> list[str]:
        """Return the variable key chunks to subscribe to: logged names and the commands."""
        commands = [name_to_chunk(name) for name in sorted(self._cmd_names)]
        return [*self._classifier.key_suffixes(), *commands]

    # ---------------------------------------------------------------------------------------
    # Session metadata

    def _counters(self) -> dict[str, int]:
        stats = self.stats
        return {name: getattr(stats, name) for name in _COUNTER_FIELDS}

    def _session_counters(self) -> dict[str, int]:
        base = self._m.counters_at_open
        return {k: v - base.get(k, 0) for k, v in self._counters().items()}

    def _write_meta(self, session: SessionWriter, meta: SessionMeta) -> None:
        data = meta.to_bytes()

        def write() -> None:
            if session.closed:
                return  # its final version is written by finish
            try:
                session.write_meta(data)
            except StorageError as err:
                self._background_failed(err)

        self._background(write)

    def _update_meta(self, now: float, **changes: Any) -> None:
        """Rewrite the open session's metadata with the current counters (and ``changes``)."""
        session, meta = self.session, self._m.meta
        if session is None or meta is None:
            return
        counters = self._session_counters()
        self._m.meta_counters = counters
        self._m.meta = dataclasses.replace(meta, counters=counters, updated=now, **changes)
        self._timers.meta = now
        self._write_meta(session, self._m.meta)

    def _background_failed(self, err: StorageError) -> None:
        """Report a failed fsync or metadata write (from the background thread)."""
        self.stats.write_errors += 1
        self.stats.last_error = str(err)
        self.debug(f"write error: {err}")

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

    def note(self, key: str, value: str) -> Outcome:
        """Set a note on the open session (its metadata's ``notes``)."""
        meta = self._m.meta
        if meta is None or self.session is None:
            return Outcome.refused("note", "no session is open")
        if not key.strip() or any(ord(c) < 32 for c in key):
            return Outcome.refused("note", "a note's key must be printable text")
        if key not in meta.notes and len(meta.notes) >= MAX_NOTES:
            return Outcome.refused("note", f"a session holds at most {MAX_NOTES} notes")
        self._update_meta(self._clock(), notes={**meta.notes, key: value})
        return Outcome.done("note", f"noted {key} on session {self.session.root}")

    def status(self) -> dict[str, Any]:
        """Return the status reply's body (any thread)."""
        session = self.session
        return {
            "vehicle": self.vehicle,
            "directory": session.directory if session is not None else None,
            "session": session.root if session is not None else None,
            **self.stats.as_dict(),
            "writing": session is not None,
            "problem": self._h.broken,
            "max_lag": self.max_lag(),
            "synced_at": self._h.synced_at,
            "max_fsync": self._h.max_fsync,
            "fsync_interval": self.config.fsync_interval,
            "clock": clock_state(self._clock()),
            "queue": self._h.queue,
            "commands": self.commands.recent(),
            "wire": WIRE_VERSION,
        }

    # ---------------------------------------------------------------------------------------
    # Outgoing

    def post(self, name: str, value: float | str) -> None:
        """Publish a message as pLogger (it comes back and is logged like any other)."""
        now = self._clock()
        self._app.published.add(name)
        self._publish(MoosMessage(name, value, now, self.app_name, "", self.vehicle))

    def debug(self, text: str) -> None:
        """Post a MOOS_DEBUG message from the recorder."""
        self.post("MOOS_DEBUG", text)

    # ---------------------------------------------------------------------------------------
    # Incoming (the hot path)

    def _var(self, name: str) -> _Var:
        verdict = self._classifier.classify(name)
        spec = self._specs.get(name)
        if spec is not None:
            period = spec.period
        elif name == self.commands.restart_var:
            period = 0.5
        else:
            period = 0.0
        var = _Var(verdict, period, name.upper() in _SYSTEM_VARS)
        if len(self._vars) > 65536:
            self._vars.clear()
            self._app.subscribed.clear()
        if verdict is not Verdict.IGNORE:
            self._app.subscribed.add(name)
        self._vars[name] = var
        return var

    def _source(self, msg: MoosMessage) -> str:
        ident = (msg.source, msg.aux, msg.community)
        text = self._sources.get(ident)
        if text is None:
            cfg = self.config
            text = source_field(
                msg.source or "?",
                msg.aux,
                msg.community,
                log_aux=cfg.log_aux_src,
                mark_external=cfg.mark_external_community_messages,
                own_community=self.vehicle,
            )
            if len(self._sources) > 4096:
                self._sources.clear()
            self._sources[ident] = text
        return text

    def handle(self, msg: MoosMessage, *, garbled: bool = False) -> None:
        """Log one received message (and act on it if it is a command)."""
        stats = self.stats
        stats.received += 1
        if garbled:
            stats.garbled += 1
        name = msg.name
        var = self._vars.get(name) or self._var(name)
        kind = type(msg.value)
        if var.kind is not kind:
            if var.kind is None:
                var.kind = kind
            else:
                stats.type_clashes += 1
        is_command = name in self._cmd_names
        now = self._clock()
        var.last_seen = now
        if var.period > 0.0:
            # The MOOSDB's minimum delivery interval: posts inside it are not delivered.
            if now - var.last_logged < var.period:
                stats.throttled += 1
                return
            var.last_logged = now
        verdict = var.verdict
        session = self.session
        if session is None:
            if verdict is not Verdict.IGNORE or var.system:
                stats.lost += 1
                self.losses.add(self._h.broken or "no-session", 1, now, name=name)
            if is_command:
                self.commands.moos(msg)
            return
        stamp = msg.time
        # The skew rule (docs/compat.md): only a time that is not finite, before LOGSTART or
        # more than 5 s ahead of the sample's arrival is replaced, by the arrival time. A
        # late sample (a backlog, here or on the way) keeps its own time. The comparisons
        # are written so that NaN fails them.
        if not (stamp >= self.logstart and stamp - now <= SKEW_TOLERANCE):
            stats.skewed += 1
            stamp = now
        offset = stamp - self.logstart
        try:
            if verdict is Verdict.ALOG:
                if self.config.async_log:
                    session.alog.write(self._line(session, offset, name, msg))
                stats.logged += 1
            elif verdict is Verdict.XLOG:
                if session.xlog is not None:
                    session.xlog.write(self._line(session, offset, name, msg))
                stats.excluded += 1
            else:
                stats.ignored += 1
            if var.system and verdict is not Verdict.IGNORE:
                value = msg.value
                if not isinstance(value, bytes):
                    session.ylog.write(format_ylog_line(offset, name, msg.source or "?", value))
            if self.synclog is not None:
                value = msg.value
                # The slog holds doubles only; a binary sample shows NaN, as a string does.
                self.synclog.update(name, "" if isinstance(value, bytes) else value)
        except StorageError as err:
            # A binary record failed: this sample's line was never written.
            self._storage_failed(err, lost=1)
        else:
            if self._unflushed_since is None:
                self._unflushed_since = now
        if is_command:
            self.commands.moos(msg)

    def unreadable(self, key: str) -> None:
        """Count a sample whose key names no MOOS variable (a malformed escape, docs/wire.md).

        It cannot be logged without a name; it is counted as garbled and lost, and the
        first one of each key is reported on MOOS_DEBUG.
        """
        stats = self.stats
        stats.received += 1
        stats.garbled += 1
        stats.lost += 1
        self.losses.add("unreadable", 1, self._clock())
        # Reported once per key; past 1024 keys only counted, so a flood of distinct bad
        # keys cannot turn into a flood of MOOS_DEBUG posts.
        if key not in self._h.unreadable and len(self._h.unreadable) < 1024:
            self._h.unreadable.add(key)
            self.debug(f"sample on {key} names no MOOS variable: not logged")

    def missed(self, name: str | None, source: str, count: int) -> None:
        """Count samples of ``name`` that publisher ``source`` sent but that never arrived.

        The transport finds them from sample-miss detection (DROP publishers, docs/wire.md).
        They are lost unless the variable is one the recorder would not have logged anyway;
        MOOS_DEBUG reports them per publisher, at most once a second (:meth:`tick`).
        """
        stats = self.stats
        stats.missed += count
        now = self._clock()
        if name is None:
            stats.lost += count
            self.losses.add("dropped", count, now)
        else:
            var = self._vars.get(name) or self._var(name)
            if var.verdict is not Verdict.IGNORE or var.system:
                stats.lost += count
                self.losses.add("dropped", count, now, name=name)
        self._h.missed[source] = self._h.missed.get(source, 0) + count

    def _line(self, session: SessionWriter, offset: float, name: str, msg: MoosMessage) -> str:
        value = msg.value
        source = self._source(msg)
        if isinstance(value, str):
            return self._fmt.string(offset, name, source, value)
        if isinstance(value, bytes):
            ref = session.write_blog(self._fmt.prefix(offset, name, source), value)
            return self._fmt.binary(offset, name, source, ref)
        return self._fmt.double(offset, name, source, value)

    # ---------------------------------------------------------------------------------------
    # Commands

    # The MOOS and control paths read commands in recorder/control.py and act through these.

    def log_request(self, argument: str) -> Outcome:
        """Log one more variable (LOG_REQUEST; ``argument`` as a ``Log =`` value).

        At most :data:`MAX_LOG_REQUESTS` variables over the recorder's life, each named in
        at most :data:`MAX_VAR_NAME` characters; a subscription the transport refuses
        (its own bound) refuses the request, which then changes nothing.
        """
        try:
            spec = parse_log_spec(argument)
        except MissionError as err:
            reason = err.reason if len(err.reason) <= 200 else err.reason[:199] + "…"
            self.debug(f"failed to process dynamic log request {quote(argument)}: {reason}")
            return Outcome.refused("log_request", err.reason[:256])
        if spec.var in self._specs or self._classifier.is_explicit(spec.var):
            self.debug("failed to process dynamic log request  - see pLogger output\n")
            return Outcome.refused("log_request", f"{spec.var[:MAX_VAR_NAME]} is logged already")
        why = None
        if len(spec.var) > MAX_VAR_NAME:
            why = f"the variable's name is {len(spec.var)} characters long: at most {MAX_VAR_NAME}"
        elif self._limits.requested >= MAX_LOG_REQUESTS:
            why = f"at most {MAX_LOG_REQUESTS} variables may be added by LOG_REQUEST"
        if why is not None:
            self.debug(f"refused dynamic log request {quote(spec.var)}: {why}")
            return Outcome.refused("log_request", why)
        did = f"now logging {spec.var}"
        if self._subscribe is not None:
            try:
                self._subscribe(spec.var)
            except RecorderError as err:
                # The transport's own bound (subscriptions): nothing was added.
                self.debug(f"refused dynamic log request {quote(spec.var)}: {err}")
                return Outcome.refused("log_request", str(err))
            except FleetlogError as err:
                # Logged if a wider subscription brings it in; the operator must know.
                self.debug(f"could not subscribe to {spec.var}: {err}")
                did += f" (but the subscription failed: {err})"
        self._classifier.add_log_var(spec.var)
        self._limits.requested += 1
        self._specs[spec.var] = spec
        self._vars.pop(spec.var, None)
        if spec.monitor:
            self.monitored.append(spec.var)
        if self.synclog is not None:
            had_free = bool(self.synclog.placeholders)
            offset = self._clock() - self.logstart
            claim = self.synclog.claim(spec.var, offset, nosync=not spec.sync)
            if claim is not None:
                if spec.sync and not had_free:
                    self.debug(f"no free slog column for {spec.var}: logged to the alog only")
                    did += " (no free slog column: alog only)"
                self._write_slog(claim.text, claim.patch)
        return Outcome.done("log_request", did)

    def copy_file(self, argument: str) -> Outcome:
        """Copy a file into the session (COPY_FILE_REQUEST), from the allowed directories.

        Refused, with a MOOS_DEBUG message that says why: a path outside the allowed
        directories (after following symlinks), a hidden file or directory (a component
        starting with ``.``, in the request or in what it resolves to), anything but a
        regular file (directories, FIFOs, devices), a file over :data:`MAX_COPY_BYTES`, and
        more than :data:`MAX_COPIES` copies in a session. The file is opened and checked
        here; its bytes are copied by the background writer, off the recording thread.
        """
        requested = argument
        refused = self._copy_refused(requested)
        if isinstance(refused, Outcome):
            return refused
        file, target_name = refused
        # The lines already written reach the OS before the copy's.
        self.flush()
        session = self.session
        if session is None:
            file.close()
            self.debug("failed to open file for writing")
            return Outcome.refused("copy_file", "no session is open")
        if self._limits.copy_session is not session:
            self._limits.copy_session, self._limits.copies = session, 0
        if self._limits.copies >= MAX_COPIES:
            file.close()
            return self._refuse_copy(requested, f"at most {MAX_COPIES} copies per session")
        self._limits.copies += 1

        def copy() -> None:
            with file:
                try:
                    session.copy_from(file, requested, MAX_COPY_BYTES)
                except (StorageError, FleetlogError) as err:
                    self.stats.write_errors += 1
                    self.debug(f"COPY_FILE_REQUEST for {clip(requested)} failed: {err}")

        self._background(copy)
        return Outcome.done("copy_file", f"copying {requested} to {target_name}")

    def _refuse_copy(self, requested: str, why: str, *, unreadable: bool = False) -> Outcome:
        self.stats.refused_copies += 1
        if unreadable:
            self.debug("failed to open file for reading")  # pLogger's words for these
        else:
            self.debug(f"refused COPY_FILE_REQUEST for {clip(requested)}: {why}")
        return Outcome.refused("copy_file", f"{requested[:256]}: {why}")

    def _copy_refused(self, requested: str) -> Outcome | tuple[Any, str]:
        """Check a copy request; return the open file and the copy's name, or the refusal."""
        try:
            target_name = copy_file_name(requested)
        except FleetlogError:
            return self._refuse_copy(requested, "it names no file", unreadable=True)
        source = Path(requested)
        if not source.is_absolute():
            source = self._cwd / source
        try:
            # Not strict: whether a file outside the allowed directories exists is none of
            # a Zenoh peer's business, so containment is decided before existence.
            resolved = source.resolve()
        except (OSError, RuntimeError, ValueError):
            return self._refuse_copy(requested, "cannot read it", unreadable=True)
        home = next((d for d in self.copy_dirs if resolved.is_relative_to(d)), None)
        if home is None:
            return self._refuse_copy(
                requested, "outside the directories the recorder may copy from"
            )
        asked = [part for part in Path(requested).parts if part not in (".", "..")]
        if any(part.startswith(".") for part in (*asked, *resolved.relative_to(home).parts)):
            return self._refuse_copy(requested, "hidden files and directories are never copied")
        flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC
        try:
            fd = os.open(resolved, flags)
        except (OSError, ValueError) as err:
            reason = err.strerror if isinstance(err, OSError) else str(err)
            return self._refuse_copy(requested, f"cannot read it ({reason})", unreadable=True)
        try:
            info = os.fstat(fd)
        except OSError:
            os.close(fd)
            raise
        if stat.S_ISREG(info.st_mode) and info.st_size <= MAX_COPY_BYTES:
            return os.fdopen(fd, "rb"), target_name
        os.close(fd)
        if stat.S_ISDIR(info.st_mode):
            return self._refuse_copy(requested, "a directory", unreadable=True)
        if not stat.S_ISREG(info.st_mode):
            return self._refuse_copy(requested, "not a regular file (a FIFO, a device or a socket)")
        return self._refuse_copy(requested, f"larger than {MAX_COPY_BYTES} bytes ({info.st_size})")

    # ---------------------------------------------------------------------------------------
    # Timers and flushing

    def tick(self) -> None:
        """Run what is due: slog rows, MONITOR and LOGGER_DIRECTORY, status, flushing."""
        now = self._clock()
        if (
            self.synclog is not None
            and self.session is not None
            and now - self._timers.last_row > self.config.sync_period
        ):
            self._timers.last_row = now
            self._write_slog(self.synclog.row(now - self.logstart))
        if now - self._timers.monitor >= MONITOR_INTERVAL:
            self._timers.monitor = now
            self._monitor(now)
            if self.session is not None:
                self.post("LOGGER_DIRECTORY", self.session.directory)
        if self._h.missed and now - self._timers.missed >= MISSED_REPORT_INTERVAL:
            self._timers.missed = now
            for source, count in self._h.missed.items():
                self.debug(
                    f"{count} samples from {source} were lost before reaching the recorder "
                    "(DROP congestion control)"
                )
            self._h.missed.clear()
        if now - self._timers.status >= STATUS_INTERVAL:
            self._timers.status = now
            self.post(self.app_name.upper() + "_STATUS", self.status_text(now))
            session = self.session
            if session is not None:
                self._h.lag += session.take_wait()
            self._h.last_lag, self._h.lag = self._h.lag, 0.0
        if self.session is None:
            if self._h.broken is not None and now >= self._h.retry_at:
                self._retry(now)
        elif self.session.removed():
            # Noticed while idle too, before the next samples would go to unlinked files.
            self._session_removed(self.session, now)
        else:
            if self.losses and now - self._h.gaps_at >= GAP_INTERVAL:
                self._write_gaps(now)
            if self.config.fsync_interval > 0 and now >= self._h.sync_due:
                self._sync(now)
        if now - self._timers.meta >= META_INTERVAL and self._m.meta is not None:
            self._timers.meta = now
            if self._session_counters() != self._m.meta_counters:
                self._update_meta(now)
        # Compressed streams close a frame only when flushed a second after the last one;
        # flushing on every tick keeps that bound when no more samples arrive.
        self.flush()

    def _write_slog(self, text: str, patch: SlotPatch | None = None) -> None:
        session = self.session
        if session is None or session.slog is None:
            return
        try:
            if patch is not None:
                session.slog.patch(patch.offset, patch.data)
            session.slog.write(text)
        except StorageError as err:
            self._storage_failed(err, lost=0)
        else:
            if self._unflushed_since is None:
                self._unflushed_since = self._clock()

    def _monitor(self, now: float) -> None:
        missing = [
            name
            for name in self.monitored
            if (var := self._vars.get(name)) is None
            or var.last_seen is None
            or now - var.last_seen > MONITOR_INTERVAL
        ]
        if not missing:
            return
        n = len(missing)
        if n == 1:
            self.debug("1 monitored variable is not being logged\n")
        else:
            self.debug(f"{n} monitored variables are not being logged\n")
        for name in missing:
            self.debug(f'Monitored Variable "{name}" is not appearing')

    def status_text(self, now: float) -> str:
        """Return the PLOGGER_STATUS text: CMOOSApp's fields, LogAuxSrc, and the counters.

        CMOOSApp's fields in its order (``cpuload``, ``memory_kb``, ``memory_max_kb``,
        ``Publishing`` and ``Subscribing`` as quoted comma-terminated lists), with
        ``Community`` after ``MOOSName``, before the lists, so a reader finds it first.
        """
        s = self.stats
        directory = self.session.directory if self.session else ""
        subscribed = self._app.subscribed | {*self._specs, *self._cmd_names}
        publishing = "".join(f"{n}," for n in sorted(self._app.published))
        subscribing = "".join(f"{n}," for n in sorted(subscribed))
        return (
            f"AppErrorFlag={'true' if s.lost else 'false'},Uptime={now - self.started:.6g},"
            f"{self._app.proc.fields()},"
            f"MOOSName={self.app_name},Community={self.vehicle},"
            f'Publishing="{publishing}",Subscribing="{subscribing}",'
            f"LogAuxSrc={'true' if self.config.log_aux_src else 'false'},"
            f"Received={s.received},Logged={s.logged},Excluded={s.excluded},"
            f"Throttled={s.throttled},Skewed={s.skewed},Garbled={s.garbled},Lost={s.lost},"
            f"Missed={s.missed},TypeClashes={s.type_clashes},WriteErrors={s.write_errors},"
            f"Sessions={s.sessions},Directory={directory}"
        )

    def flush_due(self, max_delay: float = 0.01) -> bool:
        """Return True when written lines have waited ``max_delay`` or more for a flush."""
        since = self._unflushed_since
        return since is not None and self._clock() - since >= max_delay

    def flush(self) -> None:
        """Hand what was written to the OS (compressed streams per their interval).

        A session whose directory was removed is noticed here, before its lines would go
        to files nobody can read: they are counted as lost and a new session opens.
        """
        since = self._unflushed_since
        self._unflushed_since = None
        session = self.session
        if session is None:
            return
        now = self._clock()
        if since is not None and now - since > self._h.lag:
            self._h.lag = now - since
        if session.removed():
            self._session_removed(session, now)
            return
        try:
            session.flush(now)
        except StorageError as err:
            # Lines fail only now; the streams count exactly those that never reached the file.
            self._storage_failed(err, lost=0)

    def _storage_failed(self, err: FleetlogError, *, lost: int, fallback: bool = True) -> None:
        """Count, report and fall back: a full or read-only disk must not stop the recorder.

        Args:
            err: what went wrong.
            lost: samples in hand that were not written, besides the lines the session's
                streams count as never written (those are counted here, by variable).
            fallback: drop the broken session and try pLogger's fallback (the working
                directory); False when the session is being closed anyway (it is passed
                as ``self.session`` is already cleared, see :meth:`_close_session`).
        """
        stats = self.stats
        reason = reason_of(err)
        session = self.session
        now = self._clock()
        if session is not None and fallback:
            self.session = None
            self._unflushed_since = None
            with contextlib.suppress(StorageError):
                session.close()  # writes what it can of the other streams
            self._count_unwritten(session, reason, now)
        root = session.root if session is not None else ""
        stats.lost += lost
        stats.write_errors += 1
        first = stats.last_error != str(err)
        stats.last_error = str(err)
        self.losses.add(reason, lost, now, session=root)
        if first:
            self.debug(f"write error, samples are being lost: {err}")
        if session is None or not fallback:
            return
        self._finish(session)
        if session.fallback or self._h.in_fallback or self._open_fallback() is None:
            # Nothing left to fall back to: samples are counted as lost, and a new session
            # opens by itself once the disk takes writes again (or at a LOGGER_RESTART).
            self._set_broken(reason, now)

    def _count_unwritten(self, session: SessionWriter, reason: str, now: float) -> None:
        """Count as lost, by variable, the lines a failed session never wrote."""
        for name, count in session.take_unwritten().items():
            self.stats.lost += count
            self.losses.add(reason, count, now, name=name, session=session.root)

    def _set_broken(self, reason: str, now: float) -> None:
        self._h.broken = reason
        self._h.retry_at = now + self._h.retry_wait
        self.debug(
            f"no session is open ({reason}): samples are being lost until writing works again"
        )

    def _session_removed(self, session: SessionWriter, now: float) -> None:
        """The session's directory (or its alog) was removed while recording: carry on.

        A new session opens at once with the same LOGSTART, so the lines not yet handed to
        the OS move into it unchanged (what the OS had went with the directory: the
        operator removed it). A binary line cannot move (its record went to the removed
        blog): it is counted lost.
        """
        stats = self.stats
        stats.write_errors += 1
        stats.last_error = f"the session directory {session.directory} was removed"
        pending = session.take_pending()
        self.session = None
        self._unflushed_since = None
        with contextlib.suppress(StorageError):
            session.close()
        self._m.meta = None  # nowhere to write its last version
        if session.lock is not None:
            session.lock.release()
        lost = 0

        def drop(line: str) -> None:
            nonlocal lost
            lost += 1
            fields = line.split(None, 2)
            name = fields[1] if len(fields) > 1 else None
            self.losses.add("removed", 1, now, name=name, session=session.root)

        samples = ("alog", "xlog")  # one line per sample; the ylog repeats alog lines
        for kind in samples:
            kept = []
            for line in pending.get(kind, ()):
                if "<MOOS_BINARY>" in line:
                    drop(line)
                else:
                    kept.append(line)
            pending[kind] = kept
        self.losses.add("removed", 0, now, session=session.root, always=True)
        try:
            new: SessionWriter | None = self._open_session()
        except StorageError as err:
            new = None
            stats.last_error = str(err)
        moved = 0
        for kind, lines in pending.items():
            stream = None if new is None else getattr(new, kind)
            for line in lines:
                if stream is not None:
                    stream.write(line)
                    moved += 1
                elif kind in samples:
                    drop(line)
        stats.lost += lost
        if moved and self._unflushed_since is None:
            self._unflushed_since = now
        self.debug(
            f"the session directory {session.directory} was removed while recording: "
            f"now logging to {new.directory if new else 'nothing'} ({lost} samples lost)"
        )
        if new is None:
            self._set_broken("removed", now)

    def _retry(self, now: float) -> None:
        """With no session open after a failure: open one if the disk takes writes again.

        The file system is asked every second (statvfs: read-only? space?); an attempt that
        still fails waits twice as long before the next, up to 8 s.
        """
        self._h.retry_at = now + RETRY_FIRST
        if not _writable(self.log_root):
            return
        self.logstart = now
        try:
            session = self._open_session()
        except StorageError as err:
            self.stats.last_error = str(err)
            self._h.retry_wait = min(self._h.retry_wait * 2, RETRY_MAX)
            self._h.retry_at = now + self._h.retry_wait
            return
        self.debug(f"writing works again: now logging to {session.directory}")

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

    def max_lag(self) -> float:
        """Return the longest a line waited from arrival to readable on disk, lately.

        Readable: handed to the OS (plain), in a complete unit (compressed: the arrival →
        flush and flush → unit maxima are added, an upper bound); over the last 2-4 s.
        """
        return max(self._h.lag, self._h.last_lag)

    def _open_fallback(self) -> SessionWriter | None:
        """Open a session in the working directory (pLogger's fallback) and announce it."""
        try:
            session = self._open_session(path=".")
        except StorageError as err:
            self.stats.last_error = str(err)
            self.debug(f"fallback failed too, samples are being lost: {err}")
            return None
        self.debug(f"now logging to the fallback {session.directory}")
        return session


def _writable(path: Path) -> bool:
    """Return True unless ``path``'s file system is read-only or (nearly) full.

    A directory that no longer exists may be created again (or its fallback used): True.
    """
    try:
        st = os.statvfs(path)
    except OSError:
        return True
    if st.f_flag & os.ST_RDONLY:
        return False
    return st.f_bavail * st.f_frsize >= MIN_FREE_BYTES
