"""The recorder's one command handler: PLOGGER_CMD, LOGGER_RESTART and the control service.

Every command, whatever path it came by, is read here, run through the engine, and its
outcome kept in a ring of the last 64 (``commands`` in the status), so the paths refuse,
count and report alike (docs/wire.md, "Control").

Threads: MOOS commands arrive in the recorder's drain thread (:meth:`CommandHandler.moos`)
and run there at once, as pLogger runs them. Control queries arrive in the control
queryable's own thread: ``status`` and ``ack`` are answered there (they read counters, or
append one line beside the sessions), ``prune`` runs in a thread of its own
(:mod:`fleetlog.recorder.pruning`); commands that change what is recorded are queued for
the drain thread (:meth:`CommandHandler.submit`), which runs at most one per pass between
batches of samples (:meth:`CommandHandler.run_queued`), so a flood of queries costs the
recording what as many PLOGGER_CMD posts would, and a full queue refuses at once.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.recording_modes import parse_note
from fleetlog.recorder.pruning import Pruner
from fleetlog.storage.metafile import append_ack
from fleetlog.wire.control import MAX_TEXT, CommandRecord, ControlRequest, Outcome
from fleetlog.wire.message import MoosMessage

if TYPE_CHECKING:
    from fleetlog.recorder.engine import Recorder

__all__ = [
    "MAX_COMMAND",
    "MAX_COPIES",
    "MAX_COPY_BYTES",
    "MAX_LOG_REQUESTS",
    "MAX_VAR_NAME",
    "RING_SIZE",
    "CommandHandler",
    "Reply",
    "clip",
    "quote",
]

#: outcomes kept for the status reply
RING_SIZE = 64
#: control commands waiting for the drain thread; more are refused at once
QUEUE_LIMIT = 16
#: commands that fleetlog will take once they exist (none left since issue 17)
NOT_YET: tuple[str, ...] = ()
#: PLOGGER_CMD's fleetlog tasks that take no value (docs/compat.md, "Recording modes")
_MODE_TASKS = ("PAUSE", "RESUME", "SPLIT")
#: commands run in the control thread (they do not touch what is being recorded)
_IN_CONTROL_THREAD = ("status", "ack", *NOT_YET)

# What a peer can make the recorder do is bounded; past a bound a command is refused, says
# why, and costs no more than any other (issue 10).
#: the longest PLOGGER_CMD text read (a LOG_REQUEST or a path is far shorter)
MAX_COMMAND = 4096
#: variables LOG_REQUEST may add over a recorder's life (each may need a subscription)
MAX_LOG_REQUESTS = 256
#: the longest variable name a LOG_REQUEST may add
MAX_VAR_NAME = 256
#: files COPY_FILE_REQUEST may copy into one session
MAX_COPIES = 64
#: the largest file COPY_FILE_REQUEST copies (missions, behaviour files, scripts)
MAX_COPY_BYTES = 16 << 20
#: what a MOOS_DEBUG message quotes of a peer's text
_QUOTE = 80
#: commands whose refusals the engine reports on MOOS_DEBUG itself, in pLogger's words
#: (whichever path they came by); every other refusal is reported by the handler
_SELF_REPORTED = ("log_request", "copy_file", "restart")


def clip(text: str) -> str:
    """Return ``text`` cut to about 80 characters, for MOOS_DEBUG messages."""
    if len(text) <= _QUOTE:
        return text
    return text[:_QUOTE] + f"… ({len(text)} characters)"


def quote(text: str) -> str:
    """Return ``repr(text)`` cut to about 80 characters, for MOOS_DEBUG messages."""
    if len(text) <= _QUOTE:
        return repr(text)
    return repr(text[:_QUOTE]) + f"… ({len(text)} characters)"


_STOPPING = Outcome.refused("?", "the recorder is stopping")
#: sends a control reply (from the drain thread through the recorder's outbox)
Reply = Callable[[Outcome], None]


class CommandHandler:
    """Reads, runs, counts and remembers the recorder's commands.

    Args:
        recorder: the engine the commands act upon.
        clock: the wall clock.
    """

    def __init__(self, recorder: Recorder, clock: Callable[[], float] = time.time) -> None:
        self._rec = recorder
        self._clock = clock
        self._ring: collections.deque[CommandRecord] = collections.deque(maxlen=RING_SIZE)
        self._ring_lock = threading.Lock()
        self._queue: collections.deque[tuple[ControlRequest, Reply]] = collections.deque()
        self._queue_lock = threading.Lock()
        #: the names of the two MOOS command variables (after the app name)
        self.restart_var = "LOGGER_RESTART"
        self.command_var = recorder.app_name.upper() + "_CMD"
        #: the recorder is stopping: MOOS commands are logged and counted, not run
        self.closing = False
        #: runs ``prune`` (retention of acknowledged sessions) in a thread of its own
        self.pruner = Pruner(recorder.log_root, recorder.current_session_name)

    # -- the ring

    def _remember(self, outcome: Outcome, *, when: float, via: str, source: str, text: str) -> None:
        stats = self._rec.stats
        stats.commands += 1
        if not outcome.ok:
            stats.refused_commands += 1
        record = CommandRecord.of(outcome, time=when, via=via, source=source, text=text)
        with self._ring_lock:
            self._ring.append(record)

    def recent(self) -> list[dict[str, Any]]:
        """Return the last 64 outcomes, oldest first (any thread)."""
        with self._ring_lock:
            return [r.as_json() for r in self._ring]

    # -- MOOS commands (drain thread)

    def moos(self, msg: MoosMessage) -> Outcome:
        """Run a PLOGGER_CMD or LOGGER_RESTART message, as pLogger does (§6.3, §6.5).

        Whatever the message holds, the recorder carries on: a command that fails in an
        unforeseen way is refused, reported on MOOS_DEBUG and counted like any other.
        """
        value = msg.value
        if self.closing:
            # Logged and counted, not run: a flood still queued at shutdown must not delay it.
            stats = self._rec.stats
            stats.commands += 1
            stats.refused_commands += 1
            return _STOPPING
        text = _ring_text(value)
        try:
            if msg.name == self.restart_var:
                outcome = self._rec.restart()
            else:
                outcome = self._plogger_cmd(value, msg.source)
        except Exception as err:  # a peer's command must never stop the recording
            why = f"the command failed: {err}"
            self._rec.debug(f"{msg.name} {quote(text)} failed: {quote(str(err))}")
            outcome = Outcome.refused("?", why[:256])
        self._remember(outcome, when=msg.time, via=msg.name, source=msg.source, text=text)
        return outcome

    def throttled(self, msg: MoosMessage, period: float) -> None:
        """A command that came inside its variable's delivery interval: not run, but said so.

        pLogger registers LOGGER_RESTART with a 0.5 s period, so its MOOSDB does not deliver
        a second one within 0.5 s; here the command is refused in the ring (what ``poke``
        reports) and counted, without a MOOS_DEBUG post (a flood must not become one).
        """
        value = msg.value
        text = _ring_text(value)
        restart = msg.name == self.restart_var
        task = "restart" if restart else "?"
        rule = "as pLogger registers it" if restart else "its period in the mission file"
        why = f"{msg.name} is taken at most once every {period:g} s ({rule})"
        self._remember(
            Outcome.refused(task, why), when=msg.time, via=msg.name, source=msg.source, text=text
        )

    def _plogger_cmd(self, value: float | str | bytes, msg_source: str) -> Outcome:
        rec = self._rec
        var = self.command_var
        if not isinstance(value, str):
            kind = "binary value" if isinstance(value, bytes) else "double"
            rec.debug(f"{var} must be a string, got a {kind}: ignored")
            return Outcome.refused("?", f"{var} must be a string, got a {kind}")
        if len(value) > MAX_COMMAND:
            rec.debug(f"{var} of {len(value)} characters: at most {MAX_COMMAND}, ignored")
            return Outcome.refused(
                "?", f"{var} is {len(value)} characters long: at most {MAX_COMMAND}"
            )
        bare = value.strip(" \t\r\n").upper()
        if bare in _MODE_TASKS:
            return self._mode(bare.lower())
        if bare == "SNAPSHOT":
            return rec.snapshot(f"{var} from {msg_source[:_QUOTE] or '?'}")
        head, sep, rest = value.partition("=")
        if sep and head.strip(" \t").upper() == "NOTE":
            return self._note_text(rest)
        text = value.replace(" ", "").replace("\t", "")
        task, sep, argument = text.partition("=")
        if not sep:
            rec.debug(f"{var} {quote(value)} is not TASK=VALUE: ignored")
            return Outcome.refused("?", f"{var} {quote(value)} is not TASK=VALUE")
        upper = task.upper()
        if upper == "LOG_REQUEST":
            return rec.log_request(argument)
        if upper == "COPY_FILE_REQUEST":
            return rec.copy_file(argument)
        rec.debug(f"Dynamic command {task[:_QUOTE]} is not supported")
        return Outcome.refused(
            task.lower()[:_QUOTE] or "?", f"dynamic command {task[:_QUOTE]} is not supported"
        )

    def _mode(self, cmd: str) -> Outcome:
        rec = self._rec
        if cmd == "pause":
            return rec.pause()
        if cmd == "resume":
            return rec.resume()
        return rec.split()

    def _note_text(self, text: str) -> Outcome:
        """``NOTE=key:value`` (blanks around the key and the value are trimmed)."""
        try:
            key, value = parse_note(text)
        except FormatError as err:
            return Outcome.refused("note", err.reason)
        return self._rec.note(key, value)

    # -- control requests

    def refuse_request(self, text: str, why: str, source: str = "") -> None:
        """Remember a control request that could not be read (it got an error reply)."""
        now = self._clock()
        self._rec.debug(f"refused a control request: {quote(why)}")
        self._remember(Outcome.refused("?", why), when=now, via="control", source=source, text=text)

    def submit(self, request: ControlRequest, reply: Reply) -> None:
        """Take a control request (control thread): answer it now or queue it.

        ``reply`` is called exactly once, from this thread or the drain thread.
        """
        if request.cmd == "prune":
            self.pruner.submit(lambda outcome: reply(self._record(request, outcome)))
            return
        if request.cmd in _IN_CONTROL_THREAD:
            reply(self._record(request, self._run_here(request)))
            return
        with self._queue_lock:
            if len(self._queue) < QUEUE_LIMIT:
                self._queue.append((request, reply))
                return
        busy = Outcome.refused(
            request.cmd,
            f"the recorder is busy with {QUEUE_LIMIT} earlier commands; try again shortly",
        )
        reply(self._record(request, busy))

    @property
    def pending(self) -> bool:
        """True when control commands wait for the drain thread (a cheap check)."""
        return bool(self._queue)

    def run_queued(self) -> None:
        """Run the oldest queued control command (drain thread)."""
        with self._queue_lock:
            if not self._queue:
                return
            request, reply = self._queue.popleft()
        try:
            outcome = self._run_engine(request)
        except Exception as err:  # a command must never stop the recording
            outcome = Outcome.refused(request.cmd, f"the command failed: {err}")
        reply(self._record(request, outcome))

    def cancel_queued(self, why: str) -> None:
        """Refuse every queued command (the recorder is stopping)."""
        while True:
            with self._queue_lock:
                if not self._queue:
                    return
                request, reply = self._queue.popleft()
            reply(self._record(request, Outcome.refused(request.cmd, why)))

    def _record(self, request: ControlRequest, outcome: Outcome) -> Outcome:
        if not outcome.ok and outcome.why is not None and request.cmd not in _SELF_REPORTED:
            self._rec.debug(f"refused control command {request.cmd}: {clip(outcome.why)}")
        if request.cmd != "status":  # the poll that reads the ring does not fill it
            when = request.time if request.time is not None else self._clock()
            self._remember(
                outcome, when=when, via="control", source=request.source, text=request.text
            )
        return outcome

    def _run_here(self, request: ControlRequest) -> Outcome:
        cmd = request.cmd
        if cmd == "status":
            return Outcome.done("status", "reported the recorder's status", **self._rec.status())
        if cmd == "ack":
            return self._ack(request)
        return Outcome.refused(
            cmd, f"{cmd} is not supported yet by this recorder (it comes with snapshot mode)"
        )

    def _run_engine(self, request: ControlRequest) -> Outcome:
        rec = self._rec
        cmd, args = request.cmd, request.args
        if cmd == "restart":
            return rec.restart()
        if cmd == "log_request":
            return rec.log_request(args["spec"].replace(" ", "").replace("\t", ""))
        if cmd == "copy_file":
            return rec.copy_file(args["path"])
        if cmd == "note":
            return rec.note(args["key"], args["value"])
        if cmd in ("pause", "resume", "split"):
            return self._mode(cmd)
        if cmd == "snapshot":
            return rec.snapshot(f"control from {request.source[:_QUOTE] or '?'}")
        return Outcome.refused(cmd, f"{cmd} is not a recorder command")

    def _ack(self, request: ControlRequest) -> Outcome:
        session = request.args["session"]
        files: dict[str, str] = request.args["files"]
        if session == self._rec.current_session_name():
            return Outcome.refused("ack", f"session {session!r} is still being recorded")
        try:
            append_ack(self._rec.log_root, session, files, now=self._clock(), source=request.source)
        except StorageError as err:
            return Outcome.refused("ack", str(err))
        return Outcome.done("ack", f"acknowledged {len(files)} file(s) of session {session}")


def _ring_text(value: float | str | bytes) -> str:
    """A command's value as its ring record holds it: a string as it is, else its repr.

    Of a binary value, only the bytes the record can show are written out (the record
    keeps :data:`~fleetlog.wire.control.MAX_TEXT` characters and cuts the rest): a flood of
    large binary commands costs the drain thread no copy of each whole. (Its quote is
    chosen from those bytes alone, where ``repr`` of the whole value might pick the other.)
    """
    if isinstance(value, str):
        return value
    return repr(value[:MAX_TEXT] if isinstance(value, bytes) else value)
