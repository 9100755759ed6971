"""Snapshot mode, the recorder's half: hold, trigger, and write a snapshot session.

With ``SnapshotSeconds`` set (docs/compat.md, "Snapshot mode") the recorder opens no session
at start: every sample it would log goes into a :class:`~fleetlog.recorder.snapshot.SnapshotRing`
(:meth:`SnapshotTaking._hold`, from the hot path). A SNAPSHOT (``PLOGGER_CMD = SNAPSHOT``,
the control service's ``snapshot``, or a ``SnapshotTrigger`` variable changing to its value)
opens a new session whose LOGSTART is the earliest time stamp it will hold, and writes into
it each variable's latest older value (in time order), then the ring's window, then what
arrives during ``SnapshotAfter`` seconds past the trigger; a trigger meanwhile extends that.
The samples are written by :meth:`SnapshotTaking._snapshot_tick` in slices between batches of
incoming samples, so a large ring never stalls reception; what arrives meanwhile goes to the
ring and is written after, in arrival order. Then the session closes and the ring carries on.

Time stamps are never changed but by the skew rule (docs/compat.md), applied on arrival as
when recording; a sample that arrives after the trigger stamped before the session's LOGSTART
gets its arrival time, as pLogger does for a stamp before LOGSTART.

Its state is one object on the Recorder (:class:`SnapshotState`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleetlog.errors import StorageError
from fleetlog.moos.keep_settings import SnapshotSettings, Trigger
from fleetlog.moos.patterns import Verdict
from fleetlog.moos.ylog import format_ylog_line
from fleetlog.recorder.disk import DiskKeeping
from fleetlog.recorder.snapshot import Held, SnapshotRing
from fleetlog.storage.metafile import mark_cut_sessions
from fleetlog.storage.session import SessionWriter
from fleetlog.wire.control import Outcome
from fleetlog.wire.message import MoosMessage

if TYPE_CHECKING:
    from fleetlog.recorder.control import CommandHandler

__all__ = ["MIN_INTERVAL", "SKEW_TOLERANCE", "SLICE", "SnapshotState", "SnapshotTaking"]

#: pLogger's (MOOSMsg's) skew tolerance, seconds
SKEW_TOLERANCE = 5.0
#: samples written per pass of the drain loop while a snapshot is being written
SLICE = 2000
#: the gap reason of samples evicted from the ring before a snapshot could write them
EVICTED = "snapshot-memory"
#: a new snapshot session starts at most this often (a flood of SNAPSHOTs or a trigger
#: toggling fast must not write the ring again and again); one meanwhile is refused
MIN_INTERVAL = 1.0
#: what a snapshot's reason keeps (it names a peer, which may say anything)
_WHY = 160


@dataclass
class SnapshotState:
    """Snapshot mode's state: the ring, the triggers, and the snapshot being written."""

    settings: SnapshotSettings
    #: the skew rule's LOGSTART for held samples: when snapshot mode began
    since: float
    ring: SnapshotRing = field(init=False)
    #: trigger variable -> its triggers
    triggers: dict[str, tuple[Trigger, ...]] = field(init=False)
    #: triggers whose variable holds their value now (a trigger fires on the change to it)
    matched: set[Trigger] = field(default_factory=set)
    #: a snapshot session is being written: the next sample to write, until when
    saving: bool = False
    cursor: int = 0
    until: float = 0.0
    #: the session being written (closed when it is no longer the recorder's)
    session: SessionWriter | None = None
    #: what SNAPSHOT did: sessions written, triggers taken, samples written, lost to memory
    snapshots: int = 0
    started: float = -1e300
    triggered: int = 0
    written: int = 0
    lost: int = 0
    last: str | None = None

    def __post_init__(self) -> None:
        settings = self.settings
        self.ring = SnapshotRing(settings.seconds, settings.memory)
        by_var: dict[str, list[Trigger]] = {}
        for trigger in settings.triggers:
            by_var.setdefault(trigger.var, []).append(trigger)
        self.triggers = {var: tuple(items) for var, items in by_var.items()}


class SnapshotTaking(DiskKeeping):
    """The snapshot half of the Recorder (over the disk, modes and session halves)."""

    _snap: SnapshotState | None

    commands: CommandHandler

    def _vars_verdict(self, name: str) -> tuple[Verdict, bool]:
        """Return a variable's verdict and whether it is a system variable (the Recorder's)."""
        raise NotImplementedError

    def _line(self, session: SessionWriter, offset: float, name: str, msg: MoosMessage) -> str:
        raise NotImplementedError

    # -- sessions

    def start(self) -> SessionWriter | None:
        """Open the first session, or in snapshot mode only mark cut sessions (no session).

        Raises:
            StorageError: no session directory could be created at all.
        """
        snap = self._snap
        if snap is None:
            return super().start()
        self._m.cut_sessions = mark_cut_sessions(self.log_root, self._clock())
        settings = snap.settings
        self.debug(
            f"snapshot mode: keeping the last {settings.seconds:g} s in memory "
            f"(at most {settings.memory} bytes); nothing is written until a SNAPSHOT"
        )
        return None

    def restart(self) -> Outcome:
        """LOGGER_RESTART; refused in snapshot mode (sessions come from SNAPSHOT there)."""
        if self._snap is None:
            return super().restart()
        why = "in snapshot mode a session is written by SNAPSHOT only"
        self.debug(f"LOGGER_RESTART refused: {why}")
        return Outcome.refused("restart", why)

    def split(self) -> Outcome:
        """SPLIT; refused in snapshot mode, as LOGGER_RESTART is.

        A split would cut the snapshot being written in two directories (or open one that no
        SNAPSHOT asked for), and the snapshot's rest would go to the wrong one.
        """
        if self._snap is None:
            return super().split()
        why = "in snapshot mode a session is written by SNAPSHOT only"
        self.debug(f"SPLIT refused: {why}")
        return Outcome.refused("split", why)

    def stop(self) -> None:
        """Write the rest of a snapshot being written, then close everything."""
        snap = self._snap
        if snap is not None and snap.saving and self.session is snap.session:
            # A clean stop ends the snapshot where the samples end.
            snap.until = float("inf")
            while self.session is snap.session and self._pump(snap, SLICE):
                pass
            self._end_snapshot(snap)
        if snap is not None and len(snap.ring):
            # Held, never asked for: not lost, but not silent either.
            self.debug(
                f"snapshot mode: stopping with {len(snap.ring)} samples held in memory "
                "and not written (no SNAPSHOT asked for them)"
            )
        super().stop()

    # -- the hot path

    def _hold(self, snap: SnapshotState, msg: MoosMessage, now: float) -> None:
        """Put a sample in the ring, its time stamp after the skew rule."""
        stamp = msg.time
        if not (stamp >= snap.since and stamp - now <= SKEW_TOLERANCE):
            self.stats.skewed += 1
            stamp = now
        snap.ring.add(now, stamp, msg)

    def _command(self, msg: MoosMessage) -> None:
        """A command variable's sample: a trigger's, or LOGGER_RESTART / PLOGGER_CMD."""
        snap = self._snap
        if snap is not None:
            triggers = snap.triggers.get(msg.name)
            if triggers is not None:
                self._watch(snap, triggers, msg.value)
                commands = self.commands
                if msg.name not in (commands.restart_var, commands.command_var):
                    return
        self.commands.moos(msg)

    def _watch(
        self, snap: SnapshotState, triggers: tuple[Trigger, ...], value: float | str | bytes
    ) -> None:
        """Fire the triggers whose variable changed to their value (not on every write)."""
        for trigger in triggers:
            if not trigger.matches(value):
                snap.matched.discard(trigger)
            elif trigger not in snap.matched:
                snap.matched.add(trigger)
                snap.triggered += 1
                self.snapshot(f"{trigger.text()}", via="trigger")

    # -- SNAPSHOT

    def snapshot(self, why: str = "SNAPSHOT", *, via: str = "command") -> Outcome:
        """Write the ring to a new session and record on for ``SnapshotAfter`` seconds.

        A SNAPSHOT while one is being written extends it to ``SnapshotAfter`` past this one.
        Refused outside snapshot mode, and when no session can be opened (says why).
        """
        why = "".join(c if c.isprintable() else "?" for c in why[:_WHY])
        snap = self._snap
        if snap is None:
            return Outcome.refused(
                "snapshot", "the recorder is not in snapshot mode (SnapshotSeconds is not set)"
            )
        now = self._clock()
        after = snap.settings.after
        if snap.saving and self.session is not None:
            snap.until = max(snap.until, now + after)
            snap.last = why
            return Outcome.done(
                "snapshot",
                f"extended snapshot {self.session.root} to {after:g} s past now",
                session=self.session.root,
            )
        refused = self._snapshot_refused()
        if refused is None and now - snap.started < MIN_INTERVAL:
            ago = now - snap.started
            refused = f"at most one snapshot session a second (the last started {ago:.2f} s ago)"
        if refused is not None:
            self.debug(f"SNAPSHOT ({why}) refused: {refused}")
            return Outcome.refused("snapshot", refused)
        ring = snap.ring
        older, first = ring.begin(now)
        stamps = [held[1] for held in older]
        window = ring.min_stamp(first)
        logstart = min([*stamps, now] if window is None else [*stamps, window, now])
        # A session of its own, opened by the modes' cut (a part of the recorder's mission).
        cut = self.cut_session(f"SNAPSHOT: {why}", logstart=logstart)
        session = self.session
        if not cut.ok or session is None:
            self.debug(f"SNAPSHOT ({why}) failed: {cut.why}")
            return Outcome.refused("snapshot", cut.why or "no session could be opened")
        snap.session = session
        snap.saving, snap.cursor, snap.until, snap.last = True, first, now + after, why
        ring.pin = first
        snap.snapshots += 1
        snap.started = now
        span = now - (ring.oldest() or now)
        self._note_snapshot(snap, why, span)
        for held in older:
            self._write_held(session, held)
        snap.written += len(older)
        if older and self._unflushed_since is None:
            self._unflushed_since = now
        ring.written = max(ring.written, first)
        self.debug(
            f"SNAPSHOT ({why}): writing the last {span:.3g} s and {len(older)} older values "
            f"to {Path(session.directory).name}"
        )
        return Outcome.done(
            "snapshot",
            f"started snapshot {session.root} ({len(ring)} samples, {len(older)} older values)",
            session=session.root,
            directory=session.directory,
        )

    def _snapshot_refused(self) -> str | None:
        """Why no snapshot session can open now (the disk guard has stopped writing)."""
        return self._disk_refused()

    def _stop_writing(self, now: float) -> None:
        """The disk guard stops writing: a snapshot being written ends there (counted)."""
        snap = self._snap
        if snap is None:
            super()._stop_writing(now)
            return
        if snap.saving and self.session is not None:
            self._close_session()
            self._h.broken = "low-disk"
            self._snapshot_failed(snap, now)

    def _note_snapshot(self, snap: SnapshotState, why: str, span: float) -> None:
        meta = self._m.meta
        if meta is None:
            return
        notes = {
            **meta.notes,
            "snapshot": why[:256],
            "snapshot_window": f"{snap.settings.seconds:g}",
        }
        ring = snap.ring
        if ring.counts.evicted and span < snap.settings.seconds:
            # The memory bound cut the window: the session says so itself.
            notes["snapshot_held"] = (
                f"{span:.3f} s of {snap.settings.seconds:g} s (SnapshotMemory "
                f"{snap.settings.memory} bytes; {ring.counts.evicted} samples evicted so far)"
            )
        self._update_meta(self._clock(), notes=notes)

    # -- writing

    def _snapshot_due(self) -> float:
        """Return when :meth:`_snapshot_tick` next has work (epoch; inf: nothing timed).

        While a snapshot is written, each tick writes a slice and makes a flush due (the
        drain thread then ticks again at once); its end is the time it closes.
        """
        snap = self._snap
        if snap is None or not snap.saving:
            return math.inf
        return snap.until

    def _snapshot_tick(self, now: float) -> None:
        """Write the next slice of the snapshot; close it once written past its end."""
        snap = self._snap
        if snap is None or not snap.saving:
            return
        if self.session is None:
            self._snapshot_failed(snap, now)
            return
        more = self._pump(snap, SLICE)
        snap.session = self.session  # a split may have cut it into parts
        if self.session is None:
            self._snapshot_failed(snap, now)
        elif not more and now >= snap.until:
            name = self.session.root
            if self.losses:
                self._write_gaps(now)  # this snapshot's own losses are marked in it
            self._end_snapshot(snap)
            self._close_session()
            self.debug(f"snapshot {name} written")

    def _pump(self, snap: SnapshotState, count: int) -> bool:
        """Write up to ``count`` held samples; return True if more are due now."""
        ring = snap.ring
        if snap.cursor < ring.first:
            # Evicted by the memory bound before they were written: lost, and marked.
            missed = ring.first - snap.cursor
            snap.lost += missed
            self.stats.lost += missed
            self.losses.add(EVICTED, missed, self._clock())
            snap.cursor = ring.pin = ring.first
        session = self.session
        if session is None:
            return False
        written = 0
        for seq, held in ring.since(snap.cursor, count):
            if held[0] > snap.until:
                break
            self._write_held(session, held)
            written += 1
            snap.cursor = ring.pin = seq + 1
            if self.session is not session:
                break  # the disk failed: _snapshot_tick takes it from here
        snap.written += written
        ring.written = max(ring.written, snap.cursor)
        if written and self._unflushed_since is None:
            self._unflushed_since = self._clock()
        return snap.cursor < ring.end() and written == count

    def _end_snapshot(self, snap: SnapshotState) -> None:
        snap.saving = False
        snap.session = None
        snap.ring.pin = None

    def _snapshot_failed(self, snap: SnapshotState, now: float) -> None:
        """The snapshot's session failed (the disk): count what it could not write."""
        due = snap.ring.since(snap.cursor, snap.ring.end() - snap.cursor)
        lost = sum(1 for _, held in due if held[0] <= snap.until)
        self._end_snapshot(snap)
        snap.lost += lost
        self.stats.lost += lost
        self.losses.add(self._h.broken or "write-error", lost, now)
        # No session opens by itself in snapshot mode: the next SNAPSHOT tries again.
        self._h.broken = None
        self.debug(f"the snapshot could not be written to its end: {lost} samples lost")

    def _write_held(self, session: SessionWriter, held: Held) -> None:
        """Write one held sample as :meth:`Recorder.handle` writes one (same files, counts)."""
        arrival, stamp, msg = held
        if not stamp >= self.logstart:
            self.stats.skewed += 1  # after the trigger, stamped before the LOGSTART
            stamp = arrival
        name = msg.name
        verdict, system = self._vars_verdict(name)
        offset = stamp - self.logstart
        stats = self.stats
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
                return
            value = msg.value
            if system and not isinstance(value, bytes):
                session.ylog.write(format_ylog_line(offset, name, msg.source or "?", value))
            if self.synclog is not None:
                self.synclog.update(name, "" if isinstance(value, bytes) else value)
        except StorageError as err:
            self._storage_failed(err, lost=1)

    def snapshot_status(self) -> dict[str, Any] | None:
        """Snapshot mode's state for the status reply (None outside snapshot mode)."""
        snap = self._snap
        if snap is None:
            return None
        session = snap.session
        return {
            "state": "writing" if snap.saving else "armed",
            "session": session.root if session is not None and snap.saving else None,
            "after": snap.settings.after,
            "until": snap.until if snap.saving else None,
            "triggers": [t.text() for t in snap.settings.triggers],
            "snapshots": snap.snapshots,
            "triggered": snap.triggered,
            "written": snap.written,
            "lost": snap.lost,
            "last": snap.last,
            **snap.ring.status(self._clock()),
        }
