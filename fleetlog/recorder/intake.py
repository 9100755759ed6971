"""The per-sample path of the Recorder: one received MOOS message onto its lines, counted.

:meth:`Intake.handle` is the specification of what a sample becomes: throttles, snapshot
mode, pause, the skew rule, the alog/xlog/ylog lines and the slog, commands. The fast lane
(recorder/lane.py) writes the same lines for the common samples without going through it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fleetlog.errors import StorageError
from fleetlog.moos.alog import source_field
from fleetlog.moos.patterns import Verdict
from fleetlog.moos.ylog import format_ylog_line
from fleetlog.recorder.snapshot_mode import SKEW_TOLERANCE, SnapshotTaking
from fleetlog.storage.session import SessionWriter
from fleetlog.wire.message import MoosMessage

__all__ = ["Intake", "LaneTarget", "VarState"]


@dataclass(slots=True)
class VarState:
    """Per-variable state, built once per name (the hot path reads only this)."""

    verdict: Verdict
    period: float
    system: bool
    last_logged: float = -1e300
    last_seen: float | None = None
    #: the type of the variable's first value (float, str or bytes)
    kind: type | None = None
    #: logged to the alog as it comes: no throttle, not a system variable, not a command
    plain: bool = False


#: what the fast lane writes with: the alog's ``write``, the variables' ``get``, LOGSTART and
#: the clock (:meth:`Intake.lane_open`)
LaneTarget = tuple[
    Callable[[str], None], Callable[[str], "VarState | None"], float, Callable[[], float]
]


class Intake(SnapshotTaking):
    """The Recorder's per-sample half (a mixin: the Recorder sets the attributes below)."""

    _vars: dict[str, VarState]
    _cmd_names: frozenset[str]
    _sources: dict[tuple[str, str, str], str]

    def _var(self, name: str) -> VarState:
        """Build a variable's state on its first sample (the Recorder's)."""
        raise NotImplementedError

    def _source(self, msg: MoosMessage) -> str:
        return self._source_text(msg.source, msg.aux, msg.community)

    def _source_text(self, source: str, aux: str, community: str) -> str:
        """Return the alog's source column for a message's origin (cached per origin)."""
        ident = (source, aux, community)
        text = self._sources.get(ident)
        if text is None:
            cfg = self.config
            text = source_field(
                source or "?",
                aux,
                community,
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
                if is_command:
                    # Not run, as pLogger's MOOSDB would not deliver it; but said so.
                    self.commands.throttled(msg, var.period)
                return
            var.last_logged = now
        verdict = var.verdict
        snap = self._snap
        if snap is not None:
            # Snapshot mode: held in memory, written by a SNAPSHOT (recorder/snapshot_mode.py).
            if verdict is not Verdict.IGNORE:
                if self._modes.paused:
                    stats.paused += 1  # paused: not even held
                else:
                    self._hold(snap, msg, now)
            if is_command:
                self._command(msg)
            return
        session = self.session
        if session is None or self._modes.paused:
            if verdict is not Verdict.IGNORE or var.system:
                if self._modes.paused:
                    stats.paused += 1  # not written, by the operator's choice: not lost
                else:
                    stats.lost += 1
                    self.losses.add(self._h.broken or "no-session", 1, now, name=name)
            if is_command:
                self._command(msg)
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
            self._command(msg)

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

    def _vars_verdict(self, name: str) -> tuple[Verdict, bool]:
        var = self._vars.get(name) or self._var(name)
        return var.verdict, var.system

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
    # What the fast lane (recorder/lane.py) needs: the plain case of handle, once per batch

    def lane_open(self) -> LaneTarget | None:
        """Return where the fast lane writes, or None while no sample may take it.

        A sample takes the lane only where :meth:`handle` would write its alog line and do
        nothing else: a session is open and not paused, no snapshot mode, AsyncLog on and
        no SyncLog. The answer holds until the next sample handled the general way (a
        command may change it) or the next flush, tick or command of the drain.
        """
        session = self.session
        if (
            session is None
            or self._modes.paused
            or self._snap is not None
            or self.synclog is not None
            or not self.config.async_log
        ):
            return None
        return session.alog.write, self._vars.get, self.logstart, self._clock

    def lane_formats(self, name: str, source: str, aux: str, community: str) -> tuple[str, str]:
        """Return the ``%`` formats of a double's and a string's alog line for this origin."""
        return self._fmt.line_formats(name, self._source_text(source, aux, community))

    def lane_logged(self, count: int, first: float) -> None:
        """Count ``count`` samples the lane logged, the first of them at ``first``."""
        stats = self.stats
        stats.received += count
        stats.logged += count
        if self._unflushed_since is None:
            self._unflushed_since = first
