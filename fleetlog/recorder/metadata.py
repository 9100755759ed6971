"""The open session's metadata (``.fleetlog-session.json``), kept current off the recording thread.

:class:`MetadataKeeping` is the part of :class:`~fleetlog.recorder.sessions.SessionKeeping`
that owns a session's metadata once it is open: its counters (this session's, not the
recorder's), and when it is rewritten. A rewrite is a file created, fsynced and renamed and
the directory fsynced, handed to the background writer; it happens when a counter moved, at
most every :data:`META_INTERVAL` s, or every ``IDLE_REWRITE`` s while the recorder logs
little besides its own status. Opening, closing and the last version of a session are the
session keeping's; the file's format and who reads it, :mod:`fleetlog.wire.session_meta`
and :mod:`fleetlog.storage.metafile`.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field
from operator import attrgetter
from typing import Any

from fleetlog.errors import StorageError
from fleetlog.moos.mission import LoggerConfig
from fleetlog.recorder.background import Background
from fleetlog.recorder.faults import StorageFaults
from fleetlog.recorder.stats import COUNTER_FIELDS
from fleetlog.storage.metafile import IDLE_REWRITE
from fleetlog.storage.session import SessionWriter
from fleetlog.wire.session_meta import SessionMeta

__all__ = ["META_EARLY", "META_IDLE_LINES", "META_INTERVAL", "MetaState", "MetadataKeeping"]

#: the session metadata is rewritten at most this often while counters change
META_INTERVAL = 2.0
#: ... or up to this much sooner when the drain thread is awake for other work anyway: an
#: idle recorder's own PLOGGER_STATUS changes the counters every 2 s, and without this slack
#: the rewrite drifted a few ms away from the tick that logs that line, a wake-up of its own
META_EARLY = 0.25
#: ... but only every IDLE_REWRITE s while the recorder logs little besides its own status
#: (at most this many entries since the last rewrite, no other counter moved) into a plain
#: alog: a crash's gap then starts at the last PLOGGER_STATUS in the alog's tail
#: (storage.metafile.last_status), as precisely as before, for a fifth of the rewrites
#: (each a file created, fsynced and renamed, and the directory fsynced: CPU, and flash
#: wear, on an idle vehicle)
META_IDLE_LINES = 8
#: the counters an idle recorder's own status lines move (at most META_IDLE_LINES each)
_QUIET_MOVERS = frozenset(COUNTER_FIELDS.index(name) for name in ("received", "logged"))
#: every counter of the recorder, as a tuple
_RAW_COUNTERS = attrgetter(*COUNTER_FIELDS)


@dataclass
class MetaState:
    """The open session's metadata and what it is built from."""

    recorder_id: str
    host: str
    boot: str
    meta: SessionMeta | None = None
    counters_at_open: dict[str, int] = field(default_factory=dict)
    #: when the metadata was last rewritten
    meta_at: float = 0.0
    #: every counter (:data:`_RAW_COUNTERS`) when it was last rewritten
    meta_raw: tuple[int, ...] = ()
    #: sessions found cut at start, marked by the first session's first entries
    cut_sessions: list[SessionMeta] = field(default_factory=list)
    #: set whenever a session opens or closes (a log server's warmer waits on it)
    changed: threading.Event = field(default_factory=threading.Event)


class MetadataKeeping(StorageFaults):
    """The metadata part of the session keeping (a mixin: the Recorder sets what it uses)."""

    # What it uses of the Recorder (set by Recorder.__init__).
    config: LoggerConfig
    _background: Background
    _m: MetaState

    @property
    def meta(self) -> SessionMeta | None:
        """The open session's metadata."""
        return self._m.meta

    @property
    def session_changes(self) -> threading.Event:
        """Set whenever a session opens or closes (never cleared here: the waiter clears it)."""
        return self._m.changed

    @property
    def cut_sessions(self) -> list[SessionMeta]:
        """The sessions found cut when the recorder started."""
        return self._m.cut_sessions

    def _forget_meta(self) -> None:
        self._m.meta = None

    def _counters(self) -> dict[str, int]:
        stats = self.stats
        return {name: getattr(stats, name) for name in COUNTER_FIELDS}

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
                if session.files_removed():
                    # The operator removed the session: one fault, counted once where the
                    # drain notices it (_session_removed), not again for each write in flight.
                    return
                self._background_failed(err)

        self._background(write)

    def _meta_stale(self) -> bool:
        """Return whether a counter changed since the metadata was last rewritten.

        One C call and a tuple comparison: asked at every tick and every sleep.
        """
        return _RAW_COUNTERS(self.stats) != self._m.meta_raw

    def _meta_quiet(self) -> bool:
        """Whether the counters moved as little as the recorder's own status lines move them.

        In a plain alog only (the tail of a compressed one is not read after a crash).
        """
        if self.config.compress_alogs != "none":
            return False
        old = self._m.meta_raw
        if len(old) != len(COUNTER_FIELDS):
            return False  # not rewritten since the session opened
        for i, (now, then) in enumerate(zip(_RAW_COUNTERS(self.stats), old, strict=True)):
            if now != then and (i not in _QUIET_MOVERS or now - then > META_IDLE_LINES):
                return False
        return True

    def _meta_interval(self) -> float:
        """How long after the last rewrite the stale metadata is due."""
        return IDLE_REWRITE if self._meta_quiet() else META_INTERVAL

    def _update_meta(self, now: float, **changes: Any) -> None:
        """Rewrite the open session's metadata with the current counters (and ``changes``)."""
        session, meta = self.session, self._m.meta
        if session is None or meta is None:
            return
        counters = self._session_counters()
        self._m.meta_raw = _RAW_COUNTERS(self.stats)
        self._m.meta = dataclasses.replace(meta, counters=counters, updated=now, **changes)
        self._m.meta_at = now
        self._write_meta(session, self._m.meta)

    def _background_failed(self, err: StorageError) -> None:
        """Report a failed fsync or metadata write (from the background thread)."""
        self.stats.write_errors += 1
        self.stats.last_error = str(err)
        self.debug(f"write error: {err}")

    def _meta_tick(self, now: float) -> None:
        """Rewrite the metadata if it is stale and due (the session tick's last timer)."""
        if (
            self._m.meta is not None
            and now - self._m.meta_at >= META_INTERVAL - META_EARLY  # the cheap test first
            and self._meta_stale()
            and now - self._m.meta_at >= self._meta_interval() - META_EARLY
        ):
            self._update_meta(now)

    def _meta_due(self) -> float | None:
        """When the stale metadata is due (epoch), or None while it is current."""
        if self._m.meta is not None and self._meta_stale():
            return self._m.meta_at + self._meta_interval()
        return None
