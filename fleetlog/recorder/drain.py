"""The drain thread: samples from the subscribers' FIFOs into the engine, and nothing when idle.

One thread drains the subscribers' FIFO channels (``try_recv``: no Python callback and no
file I/O in Zenoh's threads, and a full FIFO makes Zenoh hold BLOCK publishers back instead
of dropping), hands them to the :class:`~fleetlog.recorder.engine.Recorder` through its
:class:`~fleetlog.recorder.lane.Lane` (the common samples formatted straight into their
line, the others decoded and handled), and flushes plain logs as soon as a pass finds the
channels empty: at once after a pass that took nothing, within 1 ms after passes that take
samples and then find every channel empty (the recorder keeps up), within 5 ms of a line
being written while they never empty.

When the channels stay empty the thread sleeps until there is work instead of polling: each
FIFO's :class:`Inbox` then lends it to a watcher thread blocked in the FIFO's ``recv`` (no
GIL held), which takes the next sample and wakes the drain thread; the drain thread also
wakes for the engine's next timer (:meth:`Recorder.due_in`), a control command and stop.
While a watcher waits, the drain thread never reads that FIFO, so samples keep their order.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, Protocol

from fleetlog.errors import TransportError
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.lane import Lane
from fleetlog.transport.bus import MissCounter, SampleDecoder
from fleetlog.transport.session import translate_zerror

__all__ = ["Drain", "Fifo", "Inbox", "Wake"]

_FLUSH_DELAY = 0.005
#: how long a line may wait for its flush while each pass takes samples and then finds every
#: FIFO empty: a flush after every such pass would cost a write per pass at high rates
#: (a tenth of the loss-free rate); the pass after the next poll flushes it
_CAUGHT_UP = 0.001
_TICK = 0.02
#: samples handed to the lane at a time: between two such runs the drain checks whether a
#: flush is due and whether the subscriber had its slice (at 2-6 µs per sample, every
#: 0.1-0.2 ms; the checks cost 0.01 µs per sample)
_CHECK_EVERY = 32
#: the longest one subscriber's batch may hold the drain thread before the others get a
#: turn: a flood of costly commands on one key must not hold back the variables on the rest
_SLICE = 0.01
#: the wait between two passes that found the FIFOs empty, while samples still come: the
#: longest a sample waits in its FIFO then (and every pass costs a wake-up of this thread)
_POLL = 0.001
#: empty passes (_POLL apart) before the drain thread sleeps until there is work: a steady
#: stream keeps it polling, which batches samples per pass (one write per batch), and a
#: handover to a watcher thread costs a few thread switches
_SPIN = 4
#: the same after a sample woke the sleeping thread: whatever woke it came more than the
#: polls' span after the sample before, so a stream that slow gains nothing from them (an
#: idle recorder's own PLOGGER_STATUS cost four wake-ups each). One poll still catches a
#: stream of a sample a millisecond or so that was taken for an idle spell (a poll that
#: finds samples makes the thread poll ``_SPIN`` times again) ...
_SPIN_AFTER_SLEEP = 1
#: ... when the sample before came less than this long before (seconds); after a longer
#: silence (an idle recorder's own status line, a MOOS app's burst at its AppTick) the poll
#: found nothing, and the stragglers of a burst cost no more handed over by the watcher
_STREAM = 0.005
#: the longest the drain thread sleeps with nothing to do, whatever the engine says
#: (:meth:`Recorder.due_in`: its next PLOGGER_STATUS is 2 s away at most); systemd's
#: watchdog is fed at a third of WatchdogSec if that is less
_MAX_SLEEP = 2.0


class Fifo(Protocol):
    """What the drain uses of a FIFO subscriber (declared by the transport layer)."""

    @property
    def handler(self) -> Any:
        """The channel itself (it still yields what it holds once undeclared)."""

    def try_recv(self) -> Any:
        """Return the next sample, or None when empty."""

    def undeclare(self) -> None:
        """Stop reception."""


class Wake:
    """Wakes one sleeping thread: a non-blocking pipe, safe to write from a signal handler.

    ``threading.Event`` would not do: its ``set`` takes a lock that the sleeping thread may
    hold when a signal handler runs in that same thread (SIGINT stops the CLI's recorder,
    whose main thread drains). And Linux may deliver a signal to any thread, while Python
    runs its handler in the main thread only once that thread wakes: :meth:`signals` makes
    the C-level handler write to this pipe too (``signal.set_wakeup_fd``), so the sleeping
    main thread wakes at once to run it.
    """

    __slots__ = ("_closed", "_read", "_write")

    def __init__(self) -> None:
        self._read, self._write = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self._closed = False

    def set(self) -> None:
        """Wake the waiting thread, or the next to wait (any thread, a signal handler too)."""
        if self._closed:
            return
        with contextlib.suppress(BlockingIOError):  # full: woken already
            os.write(self._write, b"w")

    def wait(self, timeout: float) -> bool:
        """Wait for :meth:`set` (or a signal) at most ``timeout`` s; return whether woken."""
        ready, _, _ = select.select([self._read], [], [], timeout)
        if not ready:
            return False
        with contextlib.suppress(BlockingIOError):
            while os.read(self._read, 4096):
                pass
        return True

    @contextlib.contextmanager
    def signals(self) -> Iterator[None]:
        """Wake on any signal while in this block (main thread only; elsewhere nothing)."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
        try:
            yield
        finally:
            signal.set_wakeup_fd(previous)

    def close(self) -> None:
        """Close the pipe (later calls to :meth:`set` do nothing)."""
        self._closed = True
        for fd in (self._read, self._write):
            with contextlib.suppress(OSError):
                os.close(fd)


class Inbox:
    """One subscriber's FIFO, with a watcher that waits for its next sample while the drain sleeps.

    The watcher thread starts at the first :meth:`lend`. From ``lend`` until it has a sample
    (:attr:`lent` true) the FIFO is the watcher's: the drain thread reads it again only
    after taking :attr:`held`, the sample the watcher received, which comes first.
    """

    __slots__ = ("_armed", "_closing", "_thread", "_wake", "closed", "held", "lent", "sub")

    def __init__(self, sub: Fifo, wake: Wake) -> None:
        self.sub = sub
        self._wake = wake
        self._armed = threading.Event()
        self._thread: threading.Thread | None = None
        self._closing = False
        #: the watcher may be inside ``recv``: the FIFO is not the drain thread's to read
        self.lent = False
        #: the sample the watcher received, not yet taken by the drain thread
        self.held: Any = None
        #: the channel was found closed (undeclared) by the watcher
        self.closed = False

    def lend(self) -> None:
        """Let the watcher wait for the next sample (the drain thread is going to sleep)."""
        if self.lent or self.closed or self.held is not None:
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._watch, name="fleetlog-inbox", daemon=True)
            self._thread.start()
        self.lent = True
        self._armed.set()

    def _watch(self) -> None:
        recv = self.sub.handler.recv
        while True:
            self._armed.wait()
            self._armed.clear()
            if self._closing:
                return
            try:
                sample = recv()  # blocks without the GIL
            except Exception:  # the channel is closed and empty: the subscriber is gone
                sample = None
                self.closed = True
            # Held before the FIFO is given back: the drain thread reads ``lent`` first.
            self.held = sample
            self.lent = False
            self._wake.set()
            if self.closed:
                return

    def close(self, timeout: float = 2.0) -> None:
        """Stop the watcher; call after the subscriber was undeclared (its ``recv`` then ends).

        A sample it received in the meantime stays in :attr:`held`.
        """
        self._closing = True
        self._armed.set()
        if self._thread is not None:
            self._thread.join(timeout)


class Drain:
    """Moves samples from the inboxes to the recorder, and its timers, in one thread."""

    def __init__(
        self,
        recorder: Recorder,
        var_prefix: str,
        stop: threading.Event,
        watchdog: Callable[[float], None] | None = None,
        watchdog_every: float = _MAX_SLEEP,
    ) -> None:
        self.recorder = recorder
        self._prefix = var_prefix
        self._stop = stop
        self._watchdog = watchdog
        self._max_sleep = min(_MAX_SLEEP, watchdog_every) if watchdog else _MAX_SLEEP
        #: set by whatever has work for a sleeping drain thread (a watcher, a command, stop)
        self.wake = Wake()
        self.inboxes: list[Inbox] = []
        #: the sample-miss heartbeats' FIFO (read at each tick)
        self.beats: Fifo | None = None
        #: samples DROP publishers lost on the way (sample-miss detection, docs/wire.md)
        self.misses = MissCounter()
        #: when every subscriber was last seen empty (monotonic)
        self._drained_at = 0.0
        #: how many times the thread slept until there was work (tests, benchmarks)
        self.sleeps = 0
        #: the general way's decoder (the lane shares its caches)
        self._decoder = SampleDecoder(var_prefix)
        #: the drain's fast lane, made at the first pass (tests, benchmarks)
        self.lane: Lane | None = None
        #: whether the last :meth:`step` found every FIFO it read empty
        self.drained = True

    def add(self, sub: Fifo) -> None:
        """Drain one more subscriber (from any point of the drain thread's work)."""
        self.inboxes.append(Inbox(sub, self.wake))

    def _pump(
        self,
        inbox: Inbox,
        recv: Callable[[], Any],
        decoder: SampleDecoder,
        deadline: float | None = None,
    ) -> int:
        """Log ``inbox``'s held sample and what ``recv`` yields until None; return how many.

        Under a flood that never lets the channel empty, the deadline (monotonic, checked
        every 256 samples) is what ends the pump.
        """
        recorder = self.recorder
        count = 0
        sample = inbox.held
        inbox.held = None
        if sample is None:
            sample = recv()
        while sample is not None:
            if deadline is not None and not count & 255 and time.monotonic() > deadline:
                inbox.held = sample
                break
            info = sample.source_info
            if info is not None:
                self.misses.seen(info, sample)
            incoming = decoder.decode(sample)
            if incoming is not None:
                recorder.handle(incoming.message, garbled=incoming.garbled)
            else:
                recorder.unreadable(str(sample.key_expr))
            count += 1
            sample = recv()
        return count

    def finish(self, deadline: float) -> None:
        """Log what is still queued (shutdown): until the FIFOs stay empty or the deadline."""
        decoder = SampleDecoder(self._prefix)
        self._read_beats()
        while time.monotonic() < deadline:
            got = 0
            for inbox in self.inboxes:
                if inbox.lent:
                    continue  # empty when it was lent; its watcher hands over what comes
                with translate_zerror("subscriber"):
                    got += self._pump(inbox, inbox.sub.try_recv, decoder, deadline)
            if not got:
                self._drained_at = time.monotonic()
                break
        self._fold_misses(decoder, min_age=0.0)
        self.recorder.flush()

    def close(self) -> None:
        """Stop reception, then log what the closed channels still hold, until each is closed.

        A sample that reached the recorder is on disk: an undeclared subscriber's
        ``try_recv`` fails, its handler still yields what was queued.
        """
        inboxes, self.inboxes = self.inboxes, []
        handlers = [inbox.sub.handler for inbox in inboxes]
        subs = [inbox.sub for inbox in inboxes]
        if self.beats is not None:
            subs.append(self.beats)
            self.beats = None
        for sub in subs:
            with contextlib.suppress(TransportError), translate_zerror("undeclare"):
                sub.undeclare()
        decoder = SampleDecoder(self._prefix)
        for inbox, handler in zip(inboxes, handlers, strict=True):
            inbox.close()
            # A closed, empty channel raises instead of returning None: that is its end.
            with contextlib.suppress(TransportError), translate_zerror("subscriber"):
                self._pump(inbox, handler.try_recv, decoder)
        self._fold_misses(decoder, min_age=0.0)
        self.recorder.flush()
        self.wake.close()

    def _read_beats(self) -> None:
        """Hand the sample-miss heartbeats received so far to the miss counter."""
        beats = self.beats
        if beats is None:
            return
        with contextlib.suppress(TransportError), translate_zerror("heartbeats"):
            beat = beats.try_recv()
            while beat is not None:
                self.misses.heartbeat(beat)
                beat = beats.try_recv()

    def _fold_misses(self, decoder: SampleDecoder, min_age: float | None = None) -> None:
        """Count in the recorder what DROP publishers lost on the way (docs/wire.md)."""
        misses = self.misses
        misses.settle(self._drained_at, min_age)
        for key, source, count in misses.take():
            self.recorder.missed(decoder.name_of(key), source, count)

    def _sleep(self) -> None:
        """Sleep until a sample, a command, stop or the recorder's next timer."""
        for inbox in self.inboxes:
            inbox.lend()
        timeout = min(self._max_sleep, self.recorder.due_in(), self.misses.due_in())
        timeout = max(0.001, timeout)
        self.sleeps += 1
        self.wake.wait(timeout)

    def run(self) -> None:
        """Record until the stop event is set."""
        with self.wake.signals():
            self._run()

    def _lane(self) -> Lane:
        """Return the drain thread's lane (made at its first use)."""
        lane = self.lane
        if lane is None:
            lane = self.lane = Lane(self.recorder, self._decoder, self.misses.seen)
        return lane

    def step(self) -> int:
        """Run one pass over the FIFOs; return how many samples it handed to the recorder.

        Each FIFO is read until it is empty, its slice is over or 8192 samples were taken.
        Then what was written is flushed: at once if the pass took nothing; once the oldest
        line waited ``_CAUGHT_UP`` if every FIFO was found empty (:attr:`drained`: the
        recorder keeps up); once it waited ``_FLUSH_DELAY`` otherwise.
        """
        recorder = self.recorder
        pump = self._lane().pump
        monotonic = time.monotonic
        got = 0
        drained = True
        for inbox in self.inboxes:
            if inbox.lent:
                continue  # empty when it was lent; its watcher wakes the thread for more
            try_recv = inbox.sub.try_recv
            batch = 0
            began = monotonic()
            sample = inbox.held
            if sample is None:
                sample = try_recv()
            else:
                inbox.held = None
            while sample is not None:
                # _CHECK_EVERY samples at a time (fewer: the FIFO is empty), then whether
                # a flush is due and whether this subscriber had its slice.
                done = pump(sample, try_recv, _CHECK_EVERY)
                batch += done
                if done < _CHECK_EVERY:
                    break
                if recorder.flush_due(_FLUSH_DELAY):
                    recorder.flush()
                if monotonic() - began > _SLICE or batch >= 8192:
                    drained = False
                    break
                sample = try_recv()
            got += batch
        self.drained = drained
        if recorder.flush_due(0.0 if not got else _CAUGHT_UP if drained else _FLUSH_DELAY):
            recorder.flush()
        return got

    def _run(self) -> None:
        recorder = self.recorder
        decoder = self._decoder
        step = self.step
        monotonic = time.monotonic
        sleep = time.sleep
        next_tick = 0.0
        idle = 0
        spin = _SPIN
        #: the last pass ended in a poll (not a sleep until there is work)
        polled = False
        #: when the last pass that took samples ran
        sampled = 0.0
        stop = self._stop
        commands = recorder.commands
        watchdog = self._watchdog
        while not stop.is_set():
            got = step()
            now = monotonic()
            if commands.pending:
                # One control command per pass, between batches (as a PLOGGER_CMD costs).
                commands.run_queued()
            if not got:
                self._drained_at = now
            else:
                sampled = now
                if polled:
                    spin = _SPIN  # a poll found samples: a stream, keep polling
            if got or commands.pending:
                idle = 0
            else:
                idle += 1
            polled = False
            # Past its polls the thread runs the timers before it sleeps, so that it does
            # not wake again at once for what a pass just made due (an fsync, metadata).
            resting = idle > spin
            if now >= next_tick or resting:
                next_tick = now + _TICK
                # Heartbeats read now are trusted once the FIFOs were seen empty after this.
                self._read_beats()
                self._fold_misses(decoder)
                recorder.tick()
                if watchdog is not None:
                    watchdog(now)
            if not idle:
                continue
            if not resting:
                # Samples that come meanwhile wait for the next pass at most this long.
                sleep(_POLL)
                polled = True
            elif not stop.is_set():
                self._sleep()
                # The wake-up's sample, if any, came ``monotonic() - sampled`` after the last.
                spin = _SPIN_AFTER_SLEEP if monotonic() - sampled < _STREAM else 0
