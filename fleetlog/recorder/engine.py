"""The pLogger engine: what to log where, throttles, commands, restart, monitor, timers.

The engine has no Zenoh in it: it takes MOOS messages (:meth:`Recorder.handle`), a clock and a
``publish`` function for what pLogger posts itself (MOOS_DEBUG, LOGGER_DIRECTORY,
PLOGGER_STATUS), which come back through the subscription and get logged as pLogger's own
posts come back through the MOOSDB. Its timing (throttles, slog rows, MONITOR) is therefore
tested with a fake clock and real files.
"""

from __future__ import annotations

import os
import stat
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import FleetlogError, MissionError, RecorderError, StorageError
from fleetlog.moos.alog import LineFormatter, Variant
from fleetlog.moos.mission import LoggerConfig, LogSpec, parse_log_spec
from fleetlog.moos.naming import copy_file_name
from fleetlog.moos.patterns import NAMES_CACHED, Verdict, WildcardClassifier, name_to_chunk
from fleetlog.moos.slog import SlogTable, SlotPatch
from fleetlog.recorder.background import Background, inline
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
from fleetlog.recorder.disk import DiskGuard
from fleetlog.recorder.faults import Health
from fleetlog.recorder.intake import Intake, VarState
from fleetlog.recorder.losses import LossLedger
from fleetlog.recorder.metadata import MetaState
from fleetlog.recorder.modes import ModeState
from fleetlog.recorder.snapshot_mode import SKEW_TOLERANCE, SnapshotState
from fleetlog.recorder.stats import RecorderStats
from fleetlog.storage.metafile import boot_id, host_name
from fleetlog.storage.procinfo import ProcessMonitor
from fleetlog.storage.session import SessionWriter
from fleetlog.wire.control import Outcome
from fleetlog.wire.message import MoosMessage
from fleetlog.wire.version import WIRE_VERSION

__all__ = ["SKEW_TOLERANCE", "Recorder", "RecorderStats"]

#: MONITOR's check interval and tolerance, and LOGGER_DIRECTORY's republish interval
MONITOR_INTERVAL = 10.0
#: CMOOSApp's status period
STATUS_INTERVAL = 2.0
#: samples lost before reaching the recorder are reported on MOOS_DEBUG at most this often
MISSED_REPORT_INTERVAL = 1.0
_SYSTEM_VARS = ("MOOS_DEBUG", "MOOS_SYSTEM")

Publish = Callable[[MoosMessage], None]


@dataclass
class _Timers:
    monitor: float = 0.0
    status: float = 0.0
    missed: float = -1e300
    #: when the last slog row was written
    last_row: float = -1e300


@dataclass
class _CommandLimits:
    """What LOG_REQUEST and COPY_FILE_REQUEST have used of their bounds (issue 10)."""

    #: directories COPY_FILE_REQUEST may read from (resolved)
    copy_dirs: tuple[Path, ...] = ()
    #: asks the transport to deliver a variable added by LOG_REQUEST
    subscribe: Callable[[str], None] | None = None
    #: variables added by LOG_REQUEST so far (at most MAX_LOG_REQUESTS)
    requested: int = 0
    #: copies made by COPY_FILE_REQUEST into the session they were made in
    copy_session: SessionWriter | None = None
    copies: int = 0


@dataclass
class _AppStatus:
    """What CMOOSApp's status says beyond the counters: CPU and memory, posts, subscriptions."""

    proc: ProcessMonitor = field(default_factory=ProcessMonitor)
    #: when the app started (its Uptime)
    started: float = 0.0
    published: set[str] = field(default_factory=set)
    subscribed: set[str] = field(default_factory=set)


class Recorder(Intake):
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
        background: Background = inline,
    ) -> None:
        self.config = config
        self._background = background
        self.vehicle = vehicle
        self._publish = publish
        self._clock = clock
        self._cwd = Path.cwd() if cwd is None else cwd
        self.mission_path = mission_path
        self.app_name = config.app_name
        self.stats = RecorderStats()
        #: LOGSTART: taken at construction, before Zenoh connects, as CMOOSApp does
        self.logstart = clock()
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
        self._vars: dict[str, VarState] = {}
        self._sources: dict[tuple[str, str, str], str] = {}
        self.commands = CommandHandler(self, clock)
        #: the two command variables (LOGGER_RESTART, <APP>_CMD)
        #: (and in snapshot mode, the trigger variables: they are watched like commands)
        snapshot = config.snapshot
        triggers = [t.var for t in snapshot.triggers] if snapshot is not None else []
        commands = (self.commands.restart_var, self.commands.command_var)
        self._cmd_names = frozenset((*commands, *triggers))
        self.monitored = [s.var for s in specs.values() if s.monitor]
        sync_columns = [s.var for s in specs.values() if s.sync]
        self.synclog = (
            SlogTable(sync_columns, config.dynamic_sync_log_columns) if config.sync_log else None
        )
        self._timers = _Timers(monitor=self.logstart, status=self.logstart)
        self.session: SessionWriter | None = None
        self._unflushed_since: float | None = None
        #: what LOG_REQUEST and COPY_FILE_REQUEST have used of their bounds
        self._limits = _CommandLimits(tuple(p.resolve() for p in copy_dirs), subscribe)
        #: CMOOSApp's status fields: CPU and memory, what it posts, what it receives
        self._app = _AppStatus(started=self.logstart)
        #: split, pause, notes (recorder/modes.py)
        self._modes = ModeState.of(config.modes, self.logstart)
        #: losses not yet marked in a log (docs/compat.md, PLOGGER_GAP)
        self.losses = LossLedger()
        self._h = Health()
        self._m = MetaState(recorder_id, host_name(), boot_id())
        #: snapshot mode (None when recording as pLogger does)
        self._snap = None if snapshot is None else SnapshotState(snapshot, self.logstart)
        #: the disk guard (MinFreeDisk) and retention (KeepSessions, MaxLogSize)
        self._disk = DiskGuard(config.disk)
        # Keep the attributes above at 30 or fewer (see _Health): new state goes in a group.

    def subscription_chunks(self) -> list[str]:
        """Return the variable key chunks to subscribe to: logged names and the commands."""
        commands = [name_to_chunk(name) for name in sorted(self._cmd_names)]
        return [*self._classifier.key_suffixes(), *commands]

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
            "snapshot": self.snapshot_status(),
            "disk": self.disk_status(),
            "wire": WIRE_VERSION,
            **self.modes_status(),
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
    # Variables (the per-sample path is recorder/intake.py and recorder/lane.py)

    def _var(self, name: str) -> VarState:
        verdict = self._classifier.classify(name)
        spec = self._specs.get(name)
        if spec is not None:
            period = spec.period
        elif name == self.commands.restart_var:
            period = 0.5
        else:
            period = 0.0
        system = name.upper() in _SYSTEM_VARS
        var = VarState(verdict, period, system)
        # What the fast lane may write as it comes (recorder/lane.py): handle's plain case.
        var.plain = (
            verdict is Verdict.ALOG and period == 0.0 and not system and name not in self._cmd_names
        )
        if len(self._vars) > NAMES_CACHED:
            self._forget_vars()
        if verdict is not Verdict.IGNORE:
            self._app.subscribed.add(name)
        self._vars[name] = var
        return var

    def _forget_vars(self) -> None:
        """Start the per-variable cache again (a flood of new names), keeping what has state.

        A throttled variable keeps its last logged time and a monitored one its last seen
        time: a flood of other names must change neither what is logged nor what is reported.
        """
        monitored = set(self.monitored)
        kept = {n: v for n, v in self._vars.items() if v.period > 0.0 or n in monitored}
        self._vars.clear()
        self._vars.update(kept)
        subscribed = self._app.subscribed
        subscribed.intersection_update(kept)

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
        if self._limits.subscribe is not None:
            try:
                self._limits.subscribe(spec.var)
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
        home = next((d for d in self._limits.copy_dirs if resolved.is_relative_to(d)), None)
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
            and not self._modes.paused
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
            self._end_lag_period()
        self._disk_tick(now)
        self._snapshot_tick(now)
        self._session_tick(now)
        self._modes_tick(now)
        # Compressed streams close a frame only when flushed a second after the last one;
        # flushing on every tick keeps that bound when no more samples arrive.
        self.flush()

    def due_in(self) -> float:
        """Return how long :meth:`tick` has nothing to do (seconds; 0: call it now).

        The drain thread sleeps that long when no sample comes, instead of polling: until
        the next PLOGGER_STATUS at the latest (every 2 s, a tick that also notices the
        session directory's removal), or sooner for whatever else has a time (MONITOR, slog
        rows, fsync, metadata, compressed units, gaps, retries, the disk guard, retention,
        a split by duration, the end of a snapshot).
        """
        if self._unflushed_since is not None:
            return 0.0
        now = self._clock()
        timers = self._timers
        due = min(timers.status + STATUS_INTERVAL, timers.monitor + MONITOR_INTERVAL)
        if self._h.missed:
            due = min(due, timers.missed + MISSED_REPORT_INTERVAL)
        if self.synclog is not None and self.session is not None:
            due = min(due, timers.last_row + self.config.sync_period)
        due = min(due, self._session_due(now), self._disk_due(), self._modes_due())
        return max(0.0, min(due, self._snapshot_due()) - now)

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
            f"AppErrorFlag={'true' if s.lost else 'false'},Uptime={now - self._app.started:.6g},"
            f"{self._app.proc.fields()},"
            f"MOOSName={self.app_name},Community={self.vehicle},"
            f'Publishing="{publishing}",Subscribing="{subscribing}",'
            f"LogAuxSrc={'true' if self.config.log_aux_src else 'false'},"
            f"Received={s.received},Logged={s.logged},Excluded={s.excluded},"
            f"Throttled={s.throttled},Skewed={s.skewed},Garbled={s.garbled},Lost={s.lost},"
            f"Missed={s.missed},Paused={s.paused},"
            f"TypeClashes={s.type_clashes},WriteErrors={s.write_errors},"
            f"Sessions={s.sessions},{self._snapshot_text()}Directory={directory}"
        )

    def _snapshot_text(self) -> str:
        snap = self._snap
        if snap is None:
            return ""
        state = "writing" if snap.saving else "armed"
        return f"Snapshot={state},Held={len(snap.ring)},Evicted={snap.ring.counts.evicted},"

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
        if since is not None:
            self._h.unsynced = True
            if now - since > self._h.lag:
                self._h.lag = now - since
        if session.removed():
            self._session_removed(session, now)
            return
        try:
            session.flush(now)
        except StorageError as err:
            # Lines fail only now; the streams count exactly those that never reached the file.
            self._storage_failed(err, lost=0)
