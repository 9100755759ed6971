"""The recorder process: Zenoh in, the engine in one thread, files out.

One thread drains the subscribers' FIFO channels (``try_recv``; no callback, no file I/O in
Zenoh's threads), hands each sample to the :class:`~fleetlog.recorder.engine.Recorder`, and
flushes plain logs as soon as the channels are empty, or within 5 ms of a line being written
while they are not (the durability bound is 20 ms). A full FIFO makes Zenoh push back on
BLOCK publishers instead of dropping. What the recorder posts itself goes out from a second
thread, because its own subscriber may be the one that must be drained for that put to
complete.
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
from typing import Any, Protocol

from fleetlog.errors import FleetlogError, FormatError, RecorderError, TransportError
from fleetlog.moos.mission import LoggerConfig
from fleetlog.moos.patterns import chunk_includes, name_to_chunk, reduce_chunks
from fleetlog.recorder.background import BackgroundWriter
from fleetlog.recorder.engine import Recorder
from fleetlog.storage.catalog import disk_space
from fleetlog.transport.bus import (
    MissCounter,
    MoosPublisher,
    SampleDecoder,
    declare_fifo_subscriber,
    heartbeat_keys,
)
from fleetlog.transport.queries import (
    IncomingQuery,
    LivelinessToken,
    ServiceQueryable,
    ZenohSession,
    declare_token,
    session_zid,
)
from fleetlog.transport.services import live_vehicles
from fleetlog.transport.session import SessionOptions, open_session, translate_zerror
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
_FLUSH_DELAY = 0.005
_TICK = 0.02
#: inside a long drain batch, whether a flush is due is checked every this many samples
#: (a power of two): at 6-10 µs per sample that is every 0.2-0.3 ms, and the check (0.11 µs)
#: costs 0.003 µs per sample
_CHECK_EVERY = 32
#: the longest one subscriber's batch may hold the drain thread before the others get a
#: turn: a flood of costly commands on one key must not hold back the variables on the rest
_SLICE = 0.01


class _Fifo(Protocol):
    """What the service uses of a FIFO subscriber (declared by the transport layer)."""

    @property
    def handler(self) -> Any: ...

    def try_recv(self) -> Any: ...

    def undeclare(self) -> None: ...


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
        self._subscribers: list[_Fifo] = []
        self._chunks: set[str] = set()
        self._requested_subscribers = 0
        self._session: ZenohSession | None = None
        self._var_prefix = f"{options.root}/{name_to_chunk(options.vehicle)}/var/"
        #: samples DROP publishers lost on the way (sample-miss detection, docs/wire.md)
        self._misses = MissCounter()
        self._beats: _Fifo | None = None
        #: when every subscriber was last seen empty (monotonic)
        self._drained_at = 0.0
        #: each data subscriber's FIFO capacity
        self._fifo = max(_MIN_FIFO, options.queue)
        #: the key chunks of the command variables (their FIFO is COMMAND_QUEUE)
        self._command_chunks: set[str] = set()

    def stop(self) -> None:
        """Ask the service to finish (safe from a signal handler or another thread)."""
        self._stop.set()

    # ---------------------------------------------------------------------------------------
    def _subscribe_chunk(self, chunk: str) -> None:
        assert self._session is not None
        if any(chunk_includes(have, chunk) for have in self._chunks):
            # An overlapping second subscriber would deliver every sample twice (a LOG_REQUEST
            # for a variable a wildcard pattern already brings in, for example).
            return
        self._chunks.add(chunk)
        capacity = COMMAND_QUEUE if chunk in self._command_chunks else self._fifo
        sub = declare_fifo_subscriber(self._session, self._var_prefix + chunk, capacity)
        self._subscribers.append(sub)

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
            self._beats = declare_fifo_subscriber(session, heartbeat_keys(self._var_prefix + "*"))
            self._refuse_a_second_recorder(session)
            token = declare_token(session, service_key(opts.root, opts.vehicle, "recorder"))
            status_q = self._declare_status(session, recorder)
            recorder.start()
            control_q = self._declare_control(session, recorder, outbox)
            if opts.attach is not None:
                detach = opts.attach(session, recorder)
            if opts.freeze_gc:
                gc.collect()
                gc.freeze()
            self.ready.set()
            if on_ready is not None:
                on_ready(recorder)
            self._loop(recorder)
            # What is still queued is logged; commands in it are no longer run (a flood of
            # them would hold the shutdown past its bound).
            recorder.commands.closing = True
            self._drain(recorder, deadline=time.monotonic() + 2.0)
        finally:
            # No more commands; those still queued are refused, not left unanswered.
            for queryable in control_q:
                queryable.undeclare()
            if recorder is not None:
                recorder.commands.cancel_queued("the recorder is stopping")
            # Stop reception first, then log what the closed channels still hold: a sample
            # that reached the recorder is on disk (an undeclared subscriber's try_recv
            # fails, its handler still yields what was queued).
            handlers = [sub.handler for sub in self._subscribers]
            if self._beats is not None:
                self._subscribers.append(self._beats)
                self._beats = None
            for sub in self._subscribers:
                with contextlib.suppress(TransportError), translate_zerror("undeclare"):
                    sub.undeclare()
            self._subscribers.clear()
            try:
                if recorder is not None:
                    try:
                        self._drain_closed(recorder, handlers)
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
        return RecorderStatsView(recorder.stats.as_dict() if recorder else {}, errors)

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
            body["disk"] = disk_space(recorder.log_root)  # what `fleetlog status` shows
            try:
                query.reply(key, json.dumps(body).encode(), encoding="application/json")
            except TransportError:
                pass  # the querier is gone
            finally:
                query.finish()

        return ServiceQueryable(session, key, answer)

    def _declare_control(
        self, session: ZenohSession, recorder: Recorder, outbox: _Outbox
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

        out: list[ServiceQueryable] = []
        for key in (control, f"{control}/{PRUNE}"):
            out.append(ServiceQueryable(session, key, functools.partial(on_query, key=key)))
        return out

    def _pump(
        self,
        recv: Callable[[], Any],
        recorder: Recorder,
        decoder: SampleDecoder,
        deadline: float | None = None,
    ) -> int:
        """Log every sample ``recv`` yields until it yields None (or ``deadline``); return how many.

        Under a flood that never lets the channel empty, the deadline (monotonic, checked
        every 256 samples) is what ends the pump.
        """
        count = 0
        sample = recv()
        while sample is not None:
            if deadline is not None and not count & 255 and time.monotonic() > deadline:
                break
            info = sample.source_info
            if info is not None:
                self._misses.seen(info, sample)
            incoming = decoder.decode(sample)
            if incoming is not None:
                recorder.handle(incoming.message, garbled=incoming.garbled)
            else:
                recorder.unreadable(str(sample.key_expr))
            count += 1
            sample = recv()
        return count

    def _drain(self, recorder: Recorder, deadline: float) -> None:
        """Log what is still queued (shutdown): until the FIFOs stay empty or the deadline."""
        decoder = SampleDecoder(self._var_prefix)
        self._read_beats()
        while time.monotonic() < deadline:
            got = 0
            for sub in self._subscribers:
                with translate_zerror("subscriber"):
                    got += self._pump(sub.try_recv, recorder, decoder, deadline)
            if not got:
                self._drained_at = time.monotonic()
                break
        self._fold_misses(recorder, decoder, min_age=0.0)
        recorder.flush()

    def _drain_closed(self, recorder: Recorder, handlers: list[Any]) -> None:
        """Log what undeclared subscribers' channels still hold, until each is closed."""
        decoder = SampleDecoder(self._var_prefix)
        for handler in handlers:
            # A closed, empty channel raises instead of returning None: that is its end.
            with contextlib.suppress(TransportError), translate_zerror("subscriber"):
                self._pump(handler.try_recv, recorder, decoder)
        self._fold_misses(recorder, decoder, min_age=0.0)
        recorder.flush()

    def _read_beats(self) -> None:
        """Hand the sample-miss heartbeats received so far to the miss counter."""
        beats = self._beats
        if beats is None:
            return
        with contextlib.suppress(TransportError), translate_zerror("heartbeats"):
            beat = beats.try_recv()
            while beat is not None:
                self._misses.heartbeat(beat)
                beat = beats.try_recv()

    def _fold_misses(
        self, recorder: Recorder, decoder: SampleDecoder, min_age: float | None = None
    ) -> None:
        """Count in the recorder what DROP publishers lost on the way (docs/wire.md)."""
        misses = self._misses
        misses.settle(self._drained_at, min_age)
        for key, source, count in misses.take():
            recorder.missed(decoder.name_of(key), source, count)

    def _loop(self, recorder: Recorder) -> None:
        decoder = SampleDecoder(self._var_prefix)
        decode = decoder.decode
        handle = recorder.handle
        monotonic = time.monotonic
        next_tick = 0.0
        idle = 0
        stop = self._stop
        mask = _CHECK_EVERY - 1
        seen = self._misses.seen
        commands = recorder.commands
        watchdog = self.options.watchdog
        while not stop.is_set():
            got = 0
            for sub in self._subscribers:
                try_recv = sub.try_recv
                batch = 0
                began = monotonic()
                sample = try_recv()
                while sample is not None:
                    # Numbered samples (DROP publishers) are checked for gaps: 0.05 µs for
                    # the others (bench/miss_detection.py).
                    info = sample.source_info
                    if info is not None:
                        seen(info, sample)
                    incoming = decode(sample)
                    if incoming is not None:
                        handle(incoming.message, garbled=incoming.garbled)
                    else:
                        recorder.unreadable(str(sample.key_expr))
                    batch += 1
                    if not batch & mask:
                        if recorder.flush_due(_FLUSH_DELAY):
                            recorder.flush()
                        if monotonic() - began > _SLICE:
                            break
                    if batch >= 8192:
                        break
                    sample = try_recv()
                got += batch
            now = monotonic()
            if recorder.flush_due(0.0 if not got else _FLUSH_DELAY):
                recorder.flush()
            if commands.pending:
                # One control command per pass, between batches (as a PLOGGER_CMD costs).
                commands.run_queued()
            if not got:
                self._drained_at = now
            if now >= next_tick:
                next_tick = now + _TICK
                # Heartbeats read now are trusted once the FIFOs were seen empty after this.
                self._read_beats()
                self._fold_misses(recorder, decoder)
                recorder.tick()
                if watchdog is not None:
                    watchdog(now)
            if got:
                idle = 0
            else:
                idle += 1
                # Sleep briefly when idle; a line still reaches the OS within the bound.
                time.sleep(0.001 if idle < 200 else 0.004)


@dataclass
class RecorderStatsView:
    """The final counters of a run and the errors the outbox met."""

    stats: dict[str, int | str]
    publish_errors: list[str]

    def summary(self) -> str:
        """One line for the terminal."""
        s = self.stats
        return (
            f"received {s.get('received', 0)}, logged {s.get('logged', 0)}, "
            f"excluded {s.get('excluded', 0)}, throttled {s.get('throttled', 0)}, "
            f"skewed {s.get('skewed', 0)}, garbled {s.get('garbled', 0)}, "
            f"lost {s.get('lost', 0)} in {s.get('sessions', 0)} session(s)"
        )
