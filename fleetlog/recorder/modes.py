"""The recorder's recording modes: split, pause and resume, session notes (issue 17).

:class:`ModeKeeping` is the layer of the :class:`~fleetlog.recorder.engine.Recorder` between
its engine and its sessions (:class:`~fleetlog.recorder.sessions.SessionKeeping`):

* **The cut** (:meth:`ModeKeeping.cut_session`): close the open session and open the next
  part of the same mission (same ``mission_id``, next ``part``, same LOGSTART unless told
  otherwise, the notes carried), between two samples in the recording thread, so nothing is
  lost or written twice across it. A split is a cut; snapshot mode writes its ring into a
  session opened by a cut with an earlier LOGSTART.
* **Split** (``SplitSize``, ``SplitDuration``, ``SPLIT``): a cut when the open part's files
  reach the size on disk or the duration, checked at every tick (20 ms).
* **Pause** (``PAUSE``, ``RESUME``, ``StartPaused``): the session stays open and nothing is
  written; the samples that would have been are counted as ``paused``, not lost. The alog
  marks both ends with a ``PLOGGER_PAUSE`` entry.
* **Notes**: those given at start (mission file, command line) go on every session; one set
  at runtime (``NOTE=key:value``) on the open session and the later parts of its mission.

Why the parts keep their mission's LOGSTART: a sample stamped before a new LOGSTART would be
re-stamped as skewed, and a split must never change a time stamp. The parts of a mission
then read as one log (their offsets continue), as rosbag2's split files do.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import StorageError
from fleetlog.moos.recording_modes import MAX_NOTES, RecordingModes, check_note
from fleetlog.recorder.losses import reason_of
from fleetlog.recorder.sessions import SessionKeeping
from fleetlog.storage.session import SessionWriter
from fleetlog.wire.control import Outcome

__all__ = ["MIN_SPLIT_INTERVAL", "ModeKeeping", "ModeState"]

#: SPLIT commands are taken at most this often (each makes a directory)
MIN_SPLIT_INTERVAL = 1.0
#: the alog entry marking where a pause began and ended
PAUSE_VAR = "PLOGGER_PAUSE"


@dataclass
class ModeState:
    """What the recording modes keep (one group: the Recorder keeps 30 attributes at most)."""

    #: nothing is written while paused
    paused: bool = False
    #: when the pause began, and the ``paused`` counter then
    paused_at: float = 0.0
    paused_before: int = 0
    #: the split rule (bytes on disk, seconds)
    split_size: int | None = None
    split_duration: float | None = None
    #: the mission the open session is a part of, and its part number
    mission_id: str = ""
    part: int = 0
    #: when the open part opened (its duration is counted from here)
    part_opened: float = 0.0
    #: when the last SPLIT command was taken
    split_at: float = -1e300
    #: notes and tags of every session (mission file, command line)
    notes: dict[str, str] = field(default_factory=dict)
    tags: tuple[str, ...] = ()
    #: notes set at runtime: the open session's and its mission's later parts'
    mission_notes: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of(cls, modes: RecordingModes, now: float) -> ModeState:
        """Return the state a recorder starts with (at ``now``)."""
        return cls(
            paused=modes.start_paused,
            paused_at=now,
            split_size=modes.split_size,
            split_duration=modes.split_duration,
            notes=dict(modes.notes),
            tags=modes.tags,
        )


class ModeKeeping(SessionKeeping):
    """The recording-modes layer of the Recorder (a mixin: the Recorder sets ``_modes``)."""

    _modes: ModeState

    def _identity(self, now: float) -> dict[str, Any]:
        """Return the new session's mission id, part, notes and tags (called as it opens)."""
        modes = self._modes
        if not modes.mission_id:
            modes.mission_id = uuid.uuid4().hex
            modes.part = 0
            modes.mission_notes = {}
        modes.part += 1
        modes.part_opened = now
        return {
            "mission_id": modes.mission_id,
            "part": modes.part,
            "notes": {**modes.notes, **modes.mission_notes},
            "tags": modes.tags,
        }

    def modes_status(self) -> dict[str, Any]:
        """Return the status reply's recording-mode fields (any thread)."""
        modes = self._modes
        return {
            # the counter of the same name is ``paused_samples`` here (``paused`` in metadata)
            "paused": modes.paused,
            "paused_samples": self.stats.paused,
            "mission_id": modes.mission_id,
            "part": modes.part,
            "split_size": modes.split_size,
            "split_duration": modes.split_duration,
        }

    # ---------------------------------------------------------------------------------------
    # The cut

    def restart(self) -> Outcome:
        """LOGGER_RESTART: a new mission (part 1), as :meth:`SessionKeeping.restart` opens."""
        self._modes.mission_id = ""
        return super().restart()

    def cut_session(self, why: str, *, logstart: float | None = None) -> Outcome:
        """Close the open session and open the next part of its mission.

        Run in the recording thread, between two samples: what was handled before is in the
        closed part, what comes after in the new one. The new part keeps the LOGSTART (or
        takes ``logstart``: a snapshot's ring starts before the trigger), the mission id and
        the notes; ``.LastOpenedMOOSLogDirectory`` names it and its slog repeats the header.
        If it cannot be opened, pLogger's fallback is tried and the loss counted, as for a
        LOGGER_RESTART.

        Args:
            why: what cut it, for MOOS_DEBUG and the reply (``size``, ``duration``, ``command``).
            logstart: the new part's LOGSTART (default: the mission's).

        Returns:
            The outcome (``cmd`` ``split``), with the new ``session``, ``directory`` and
            ``part``.
        """
        old = self.session
        self.flush()
        if old is not None:
            self._close_session()
        if logstart is not None:
            self.logstart = logstart
        new: SessionWriter | None
        try:
            new = self._open_session()
        except StorageError as err:
            self._storage_failed(err, lost=0)
            new = self._open_fallback()
            if new is None:
                self._set_broken(reason_of(err), self._clock())
        if new is None:
            return Outcome.refused("split", f"no session could be opened: {self.stats.last_error}")
        part = self._modes.part
        closed = f" after {Path(old.directory).name}" if old is not None else ""
        self.debug(f"split ({why}): now logging part {part} to {Path(new.directory).name}{closed}")
        return Outcome.done(
            "split",
            f"started part {part} of the mission in session {new.root} ({why})",
            session=new.root,
            directory=new.directory,
            part=part,
        )

    def split(self) -> Outcome:
        """SPLIT: cut the session now (at most once a second)."""
        now = self._clock()
        since = now - self._modes.split_at
        if 0 <= since < MIN_SPLIT_INTERVAL:
            return Outcome.refused(
                "split", f"the last split was {since:.2f} s ago: at most one a second"
            )
        if self.session is None:
            return Outcome.refused("split", f"no session is open ({self.broken or 'stopped'})")
        if not self.config.file_timestamp:
            return Outcome.refused(
                "split", "FileTimeStamp = false: a new part would overwrite the session"
            )
        self._modes.split_at = now
        return self.cut_session("command")

    def _modes_due(self) -> float:
        """Return when :meth:`_modes_tick` next has work (epoch; inf: nothing timed)."""
        modes = self._modes
        if self.session is None or modes.paused or modes.split_duration is None:
            return math.inf
        return modes.part_opened + modes.split_duration

    def _modes_tick(self, now: float) -> None:
        """Split the open part if it reached its size or duration (never while paused)."""
        modes = self._modes
        session = self.session
        if session is None or modes.paused:
            return
        why = None
        if modes.split_duration is not None and now - modes.part_opened >= modes.split_duration:
            why = "duration"
        elif modes.split_size is not None:
            self.flush()  # what was written counts now, not at the next tick
            if self.session is session and session.disk_bytes() >= modes.split_size:
                why = "size"
        if why is not None:
            self.cut_session(why)

    # ---------------------------------------------------------------------------------------
    # Pause

    def _write_gaps(self, now: float) -> None:
        """Mark losses in the alog, except while paused (they are marked on resume)."""
        if not self._modes.paused:
            super()._write_gaps(now)

    def _mark(self, text: str) -> None:
        """Write a PLOGGER_PAUSE entry into the open session's alog."""
        session = self.session
        if session is None:
            return
        now = self._clock()
        offset = max(now - self.logstart, 0.0)
        try:
            session.alog.write(self._fmt.string(offset, PAUSE_VAR, self.app_name, text))
        except StorageError as err:
            self._storage_failed(err, lost=0)
            return
        self.flush()

    def pause(self) -> Outcome:
        """PAUSE: write nothing from now on; count what is not written as ``paused``."""
        modes = self._modes
        if modes.paused:
            return Outcome.done("pause", "recording was paused already", paused=True)
        self._mark("paused")
        modes.paused = True
        modes.paused_at = self._clock()
        modes.paused_before = self.stats.paused
        self._update_meta(modes.paused_at)
        self.debug("recording paused: nothing is written until RESUME")
        return Outcome.done("pause", "paused recording", paused=True)

    def resume(self) -> Outcome:
        """RESUME: write again; the alog says how many samples the pause did not write."""
        modes = self._modes
        if not modes.paused:
            return Outcome.done("resume", "recording was not paused", paused=False)
        modes.paused = False
        now = self._clock()
        unwritten = self.stats.paused - modes.paused_before
        self._mark(f"resumed,unwritten={unwritten},from={modes.paused_at:.3f},to={now:.3f}")
        self._update_meta(now)
        self.debug(f"recording resumed ({unwritten} samples were not written while paused)")
        return Outcome.done(
            "resume", f"resumed recording ({unwritten} samples not written)", paused=False
        )

    # ---------------------------------------------------------------------------------------
    # Notes

    def note(self, key: str, value: str) -> Outcome:
        """Set a note on the open session and its mission's later parts (``NOTE=key:value``)."""
        meta = self.meta
        session = self.session
        if meta is None or session is None:
            return Outcome.refused("note", "no session is open")
        why = check_note(key, value)
        if why is not None:
            return Outcome.refused("note", why)
        if key not in meta.notes and len(meta.notes) >= MAX_NOTES:
            return Outcome.refused("note", f"a session holds at most {MAX_NOTES} notes")
        self._modes.mission_notes[key] = value
        self._update_meta(self._clock(), notes={**meta.notes, key: value})
        return Outcome.done("note", f"noted {key} on session {session.root}")
