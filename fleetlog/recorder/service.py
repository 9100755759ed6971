"""The recorder process: Zenoh in, the engine in one thread, files out.

One thread drains the subscribers' FIFO channels into the
:class:`~fleetlog.recorder.engine.Recorder` (:mod:`fleetlog.recorder.drain`: no callback and no
file I/O in Zenoh's threads; asleep when there is nothing to do). What the recorder posts
itself goes out from a second thread, because its own subscriber may be the one that must be
drained for that put to complete.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import json
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fleetlog.errors import FleetlogError, FormatError, RecorderError, TransportError
from fleetlog.moos.mission import LoggerConfig
from fleetlog.moos.patterns import chunk_includes, name_to_chunk, reduce_chunks
from fleetlog.recorder.background import BackgroundWriter
from fleetlog.recorder.drain import Drain, Wake
from fleetlog.recorder.engine import Recorder
from fleetlog.storage.catalog import disk_space
from fleetlog.transport.bus import declare_fifo_subscriber, heartbeat_keys
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.queries import (
    IncomingQuery,
    LivelinessToken,
    ServiceQueryable,
    ZenohSession,
    declare_token,
    session_zid,
)
from fleetlog.transport.services import live_vehicles
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.control import (
    CONTROL,
    MAX_REQUEST,
    PRUNE,
    Outcome,
    check_command_key,
    parse_control_request,
)
from fleetlog.wire.keys import service_key
from fleetlog.wire.message import MoosMessage

__all__ = ["RecorderService", "ServiceOptions"]

#: more subscriptions than this become one subscription to every variable, filtered here
MAX_SUBSCRIBERS = 8
#: subscribers LOG_REQUEST may add (a request whose variable is already covered adds none)
MAX_REQUEST_SUBSCRIBERS = 32
#: samples received but not yet logged that the recorder may hold, in all its subscribers'
#: FIFOs together (a full FIFO makes Zenoh hold BLOCK publishers back). What a SIGKILL
#: loses is bounded by time, not by a count: this is about 0.15 s at this machine's 50k
#: samples/s, and stays under a second for a recorder 6 times slower (docs/reliability.md).
QUEUE = 8192
#: no subscriber's FIFO holds fewer samples than this
_MIN_FIFO = 512
#: the FIFO of a subscription to the command variables alone (PLOGGER_CMD, LOGGER_RESTART):
#: outside the queue bound, because samples from one link reach every FIFO through one Zenoh
#: thread, and a flood of commands that filled a small FIFO would hold back the data behind
#: it (tests/recorder/test_hostile.py); commands are rare otherwise
COMMAND_QUEUE = 65536


@dataclass
class ServiceOptions:
    """How the recorder process runs (beyond the pLogger configuration)."""

    vehicle: str
    root: str = "fleet"
    zenoh: SessionOptions = field(default_factory=SessionOptions)
    mission_path: Path | None = None
    copy_dirs: tuple[Path, ...] = ()
    cwd: Path | None = None
    #: started once the first session is open, with the Zenoh session and the recorder;
    #: returns the function that stops it (the CLI attaches the log server here, so the
    #: recorder layer does not depend on the query layer)
    attach: Callable[[ZenohSession, Recorder], Callable[[], None]] | None = None
    #: called from the drain loop at every tick (``time.monotonic()``): feeds systemd's
    #: watchdog, so that a hung drain loop gets the service restarted, not only a dead one
    watchdog: Callable[[float], None] | None = None
    #: the longest the drain loop may go without calling ``watchdog`` when idle (seconds):
    #: a third of systemd's WatchdogSec
    watchdog_every: float = 1.0
    #: samples received but not yet logged that the recorder may hold (all FIFOs together)
    queue: int = QUEUE
    #: once started, collect and then freeze the process's objects out of the cyclic GC
    #: (``gc.freeze``), so that a full collection does not walk the start-up objects: it
    #: took 5-8 ms of CPU in a started recorder, a third of the 20 ms flush bound, and
    #: none after the freeze. Process-wide: leave it off when embedding the service.
    freeze_gc: bool = True


class _Outbox:
    """Publishes the recorder's own posts, and sends control replies, from a thread of their own.

    Neither may wait in the drain thread: a put may need the recorder's own subscriber
    drained, and a reply may wait for a congested link.
    """

    def __init__(self, publisher: MoosPublisher, on_error: Callable[[str], None]) -> None:
        self._publisher = publisher
        self._queue: queue.Queue[MoosMessage | Callable[[], None] | None] = queue.Queue()
        self._on_error = on_error
        self._thread = threading.Thread(target=self._run, name="fleetlog-outbox", daemon=True)
        self._thread.start()

    def put(self, message: MoosMessage) -> None:
        self._queue.put(message)

    def call(self, job: Callable[[], None]) -> None:
        """Run ``job`` in the outbox thread (a control reply)."""
        self._queue.put(job)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                if isinstance(item, MoosMessage):
                    self._publisher.send(item)
                else:
                    item()
            except Exception as err:  # the recorder's own posts must outlive any one failure
                what = item.name if isinstance(item, MoosMessage) else "a control reply"
                self._on_error(f"could not post {what}: {err}")

    def close(self, timeout: float = 5.0) -> None:
        self._queue.put(None)
        self._thread.join(timeout)


class RecorderService:
    """Runs a recorder on a Zenoh session until :meth:`stop` is called."""

    def __init__(self, config: LoggerConfig, options: ServiceOptions) -> None:
        self.config = config
        self.options = options
        self._stop = threading.Event()
        self.ready = threading.Event()
        self.recorder: Recorder | None = None
        #: the drain thread's work (created with the recorder)
        self._drain: Drain | None = None
        self._chunks: set[str] = set()
        self._requested_subscribers = 0
        self._session: ZenohSession | None = None
        self._var_prefix = f"{options.root}/{name_to_chunk(options.vehicle)}/var/"
        #: each data subscriber's FIFO capacity
        self._fifo = max(_MIN_FIFO, options.queue)
        #: the key chunks of the command variables (their FIFO is COMMAND_QUEUE)
        self._command_chunks: set[str] = set()

    def stop(self) -> None:
        """Ask the service to finish (safe from a signal handler or another thread)."""
        self._stop.set()
        drain = self._drain
        if drain is not None:
            drain.wake.set()

    # ---------------------------------------------------------------------------------------
    def _subscribe_chunk(self, chunk: str) -> None:
        assert self._session is not None
        assert self._drain is not None
        if any(chunk_includes(have, chunk) for have in self._chunks):
            # An overlapping second subscriber would deliver every sample twice (a LOG_REQUEST
            # for a variable a wildcard pattern already brings in, for example).
            return
        self._chunks.add(chunk)
        capacity = COMMAND_QUEUE if chunk in self._command_chunks else self._fifo
        sub = declare_fifo_subscriber(self._session, self._var_prefix + chunk, capacity)
        self._drain.add(sub)

    def _subscribe_var(self, name: str) -> None:
        """A LOG_REQUEST asks for one more variable.

        Raises:
            RecorderError: it needs a subscriber of its own and the recorder holds
                :data:`MAX_REQUEST_SUBSCRIBERS` already (the drain thread visits every
                subscriber on every pass, so each one costs every sample a little).
        """
        chunk = name_to_chunk(name)
        if not any(chunk_includes(have, chunk) for have in self._chunks):
            if self._requested_subscribers >= MAX_REQUEST_SUBSCRIBERS:
                msg = (
                    f"the recorder holds {MAX_REQUEST_SUBSCRIBERS} subscriptions for LOG_REQUEST "
                    "already (a WildcardPattern in the mission covers many variables at once)"
                )
                raise RecorderError(msg)
            self._requested_subscribers += 1
        self._subscribe_chunk(chunk)

    def _initial_chunks(self, recorder: Recorder) -> list[str]:
        chunks = list(recorder.subscription_chunks())
        chunks = reduce_chunks(chunks)
        if len(chunks) > MAX_SUBSCRIBERS:
            # One FIFO to drain beats dozens; the classifier filters exactly on arrival.
            return ["*"]
        return chunks

    def run(self, on_ready: Callable[[Recorder], None] | None = None) -> RecorderStatsView:
        """Record until stopped; return the final counters.

        Raises:
            TransportError: Zenoh could not be opened.
            StorageError: no session directory could be created.
        """
        opts = self.options
        session = open_session(opts.zenoh)
        self._session = session
        publisher = MoosPublisher(session, opts.root, opts.vehicle, self.config.app_name)
        errors: list[str] = []
        outbox = _Outbox(publisher, errors.append)
        background = BackgroundWriter(errors.append)
        token: LivelinessToken | None = None
        status_q: ServiceQueryable | None = None
        control_q: list[ServiceQueryable] = []
        recorder: Recorder | None = None
        detach: Callable[[], None] | None = None
        try:
            recorder = Recorder(
                self.config,
                vehicle=opts.vehicle,
                publish=outbox.put,
                mission_path=opts.mission_path,
                cwd=opts.cwd,
                copy_dirs=opts.copy_dirs,
                subscribe=self._subscribe_var,
                recorder_id=session_zid(session),
                background=background.submit,
            )
            self.recorder = recorder
            drain = Drain(
                recorder, self._var_prefix, self._stop, opts.watchdog, opts.watchdog_every
            )
            self._drain = drain
            chunks = self._initial_chunks(recorder)
            self._command_chunks = {
                name_to_chunk(recorder.commands.restart_var),
                name_to_chunk(recorder.commands.command_var),
            }
            # The queue bound is shared by the data FIFOs: each gets its part (a LOG_REQUEST's
            # later one gets a part too; at most a few are ever added).
            data = [c for c in chunks if c not in self._command_chunks]
            self._fifo = max(_MIN_FIFO, opts.queue // max(1, len(data)))
            for chunk in chunks:
                self._subscribe_chunk(chunk)
            recorder.queue = self._fifo * max(1, len(data))
            drain.beats = declare_fifo_subscriber(session, heartbeat_keys(self._var_prefix + "*"))
            self._refuse_a_second_recorder(session)
            token = declare_token(session, service_key(opts.root, opts.vehicle, "recorder"))
            status_q = self._declare_status(session, recorder)
            recorder.start()
            control_q = self._declare_control(session, recorder, outbox, drain.wake)
            if opts.attach is not None:
                detach = opts.attach(session, recorder)
            if opts.freeze_gc:
                gc.collect()
                gc.freeze()
            self.ready.set()
            if on_ready is not None:
                on_ready(recorder)
            drain.run()
            # What is still queued is logged; commands in it are no longer run (a flood of
            # them would hold the shutdown past its bound).
            recorder.commands.closing = True
            drain.finish(deadline=time.monotonic() + 2.0)
        finally:
            # No more commands; those still queued are refused, not left unanswered.
            for queryable in control_q:
                queryable.undeclare()
            if recorder is not None:
                recorder.commands.cancel_queued("the recorder is stopping")
            try:
                if recorder is not None:
                    try:
                        if self._drain is not None:
                            # Stop reception, then log what the closed channels still hold.
                            self._drain.close()
                    finally:
                        recorder.stop()
                # The closed session's fsync and last metadata: before the process ends.
                if not background.close():
                    errors.append("the session files could not be synced within 30 s")
            finally:
                # Whatever failed above, Zenoh is closed: a live session hangs the exit.
                if detach is not None:
                    with contextlib.suppress(FleetlogError):
                        detach()
                if status_q is not None:
                    status_q.undeclare()
                if token is not None:
                    token.undeclare()
                outbox.close()
                publisher.close()
                session.close()
                self._session = None
        return RecorderStatsView(
            recorder.stats.as_dict() if recorder else {},
            errors,
            recorder.snapshot_status() if recorder else None,
        )

    def _refuse_a_second_recorder(self, session: ZenohSession) -> None:
        """Refuse to start when a recorder of the same vehicle already answers.

        Two recorders of one vehicle would log each other's posts and both answer shore;
        once both tokens exist neither can tell, so the check comes before ours is declared.
        A peer that connects later is not seen.

        Raises:
            RecorderError: another recorder of this vehicle is up.
        """
        vehicle = self.options.vehicle
        # Asked on this vehicle's own key: the security profile lets a vehicle ask no other.
        up = live_vehicles(session, self.options.root, ("recorder",), timeout=1.0, vehicle=vehicle)
        if vehicle in up:
            msg = (
                f"a recorder of vehicle {vehicle!r} is already running "
                f"({service_key(self.options.root, vehicle, 'recorder')} answers); "
                "stop it or record another --vehicle"
            )
            raise RecorderError(msg)

    def _declare_status(self, session: ZenohSession, recorder: Recorder) -> ServiceQueryable:
        # A queryable drained by a thread of its own, not a callback: a callback would run
        # on Zenoh's network thread and wait for the GIL the busy engine holds, stalling the
        # link that carries the samples.
        key = service_key(self.options.root, self.options.vehicle, "status")

        def answer(query: IncomingQuery) -> None:
            body = recorder.status()
            # What `fleetlog status` shows (free, total, now) over the guard's own figures.
            body["disk"] = {**body["disk"], **(disk_space(recorder.log_root) or {})}
            try:
                query.reply(key, json.dumps(body).encode(), encoding="application/json")
            except TransportError:
                pass  # the querier is gone
            finally:
                query.finish()

        return ServiceQueryable(session, key, answer)

    def _declare_control(
        self, session: ZenohSession, recorder: Recorder, outbox: _Outbox, wake: Wake
    ) -> list[ServiceQueryable]:
        """The control service (docs/wire.md): read here, run by the one command handler.

        This thread only reads the request (at most 64 KiB) and hands it over; commands
        that change the recording run in the drain thread, one per pass, and their replies
        go out from the outbox thread, so neither Zenoh's threads nor the drain thread wait.
        ``prune`` is taken only on ``control/prune``, every other command only on
        ``control``: access control grants deleting on a key of its own.
        """
        control = service_key(self.options.root, self.options.vehicle, CONTROL)
        commands = recorder.commands

        def on_query(query: IncomingQuery, key: str) -> None:
            payload = query.payload(MAX_REQUEST)
            try:
                request = parse_control_request(payload, query.parameters)
                check_command_key(request, pruning=key != control)
            except FormatError as err:
                text = (payload or b"").decode("utf-8", "replace") or query.parameters
                commands.refuse_request(text, str(err))
                query.reply_err(str(err))
                query.finish()
                return

            def send(outcome: Outcome) -> None:
                try:
                    query.reply(key, outcome.reply(), encoding="application/json")
                except TransportError:
                    pass  # the querier is gone
                finally:
                    query.finish()

            here = threading.get_ident()

            def reply(outcome: Outcome) -> None:
                if threading.get_ident() == here:
                    send(outcome)  # answered in this thread (status, ack, refusals)
                else:
                    outbox.call(lambda: send(outcome))  # never from the drain thread

            commands.submit(request, reply)
            wake.set()  # a sleeping drain thread runs it now

        out: list[ServiceQueryable] = []
        for key in (control, f"{control}/{PRUNE}"):
            out.append(ServiceQueryable(session, key, functools.partial(on_query, key=key)))
        return out


@dataclass
class RecorderStatsView:
    """The final counters of a run and the errors the outbox met."""

    stats: dict[str, int | str]
    publish_errors: list[str]
    #: snapshot mode's state at the end (None outside snapshot mode)
    snapshot: dict[str, Any] | None = None

    def summary(self) -> str:
        """One line for the terminal: every sample received is accounted for in it."""
        s = self.stats
        line = (
            f"received {s.get('received', 0)}, logged {s.get('logged', 0)}, "
            f"excluded {s.get('excluded', 0)}, throttled {s.get('throttled', 0)}, "
            f"skewed {s.get('skewed', 0)}, garbled {s.get('garbled', 0)}, "
            f"lost {s.get('lost', 0)} in {s.get('sessions', 0)} session(s)"
        )
        # Samples deliberately not written are not lost, but the operator must see them.
        if s.get("paused"):
            line += f"; paused {s['paused']} (not written while paused)"
        snap = self.snapshot
        if snap is not None:
            line += (
                f"; snapshot mode: {snap.get('snapshots', 0)} snapshot(s), "
                f"{snap.get('samples', 0)} held in memory at the end and "
                f"{snap.get('unsaved', 0)} past the window never written (no SNAPSHOT), "
                f"{snap.get('evicted', 0)} evicted by the memory bound"
            )
        return line
