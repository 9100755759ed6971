"""The player: uPlayBack's engine, paced by an injected clock, publishing through a function.

Time is log time, absolute (LOGSTART + offset), so several vehicles play on one clock. While
playing, the position is ``anchor_log + (now - anchor_now) * rate``; every pause, rate change,
seek or choke re-anchors, so the schedule never drifts. An entry is due when the position
reaches its time; the player waits for that with :meth:`Clock.wait` (the real clock sleeps,
then spins for the last millisecond), publishes it, and moves on. As fast as possible, nothing
waits.

What uPlayBack does and this keeps (MOOS_FORMAT.md §8), besides what it publishes
(:mod:`fleetlog.replayer.output`):

* ``PLAYBACK_DB_TIME``'s value is the log time at the end of its tick (as fast as possible:
  the entry's time);
* PLAYBACK_CHOKE: :meth:`Player.heartbeat` takes a client's heartbeat (its own clock's time);
  while a heartbeat has been seen and the newest one is more than 2 s old, playback does not
  advance. A seek forgets the heartbeat, as ``GotoTime`` does.

Where it differs: entries are published one by one at their own time instead of in 10 ms
batches (within a batch uPlayBack posts newest first); values are read by the §12 reader rule
(multi-line values, empty strings and leading spaces survive; uPlayBack drops the first two
and keeps pLogger's terminator space); duplicates are dropped (see
:mod:`fleetlog.replayer.schedule`).

Commands (pause, rate, seek, step) are applied between two entries by the mixin in
:mod:`fleetlog.replayer.player_commands`.

Threads: :meth:`Player.run` runs in one thread; :meth:`Player.submit`,
:meth:`Player.heartbeat` and :meth:`Player.status` may be called from any other. Periodic
work such as a progress display runs in the player's thread through
:attr:`Player.idle_hooks`, when the next entry leaves time for it.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from itertools import chain

from fleetlog.errors import ReplayError, StorageError
from fleetlog.moos.alog import BinaryRef
from fleetlog.replayer.clock import Clock
from fleetlog.replayer.control import (
    Command,
    Stop,
)
from fleetlog.replayer.filters import EntryFilter
from fleetlog.replayer.inputs import ReplayInput
from fleetlog.replayer.items import KEY, LATE, ORIGIN, SOURCE, TIME, VALUE, Item
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.output import Output, Prepare, Publish, Senders
from fleetlog.replayer.player_commands import PlayerCommands
from fleetlog.replayer.report import Lateness, State, Status, Summary, VehicleCounts
from fleetlog.replayer.schedule import Schedule
from fleetlog.wire.message import Kind

__all__ = ["Player"]

_MAX_ERRORS = 5
#: The idle hooks (progress display, status publication) run this often, seconds...
IDLE_PERIOD = 0.25
#: ...when the next entry is at least this far off...
IDLE_SLACK = 0.005
#: ...or, if entries never leave that much room, after this long anyway.
IDLE_FORCE = 1.0


class Player(PlayerCommands):
    """Replays inputs on one clock; see the module docstring.

    Args:
        inputs: the open inputs (not closed here).
        publish: called for every message, with the vehicle to publish under.
        clock: the clock to pace by.
        options: how to play.
        prepare: called once per vehicle, variable and type before its first publication,
            while the player has time to spare (at the start, or waiting for an entry).
        senders: makes the senders that publish the entries (a replay link's); without,
            entries go to ``publish`` as messages.
    """

    def __init__(
        self,
        inputs: Sequence[ReplayInput],
        publish: Publish,
        clock: Clock,
        options: PlayOptions | None = None,
        prepare: Prepare | None = None,
        senders: Senders | None = None,
    ) -> None:
        if not inputs:
            msg = "nothing to replay"
            raise ReplayError(msg)
        self.options = options or PlayOptions()
        self.options.check()
        self.inputs = inputs
        self._out = Output(publish, prepare, senders)
        #: Work for the player's own thread when it has time to spare (redraw a progress
        #: line, publish the status): done here, not in another thread, because another
        #: thread holding the GIL for a millisecond delays the next entry by as much.
        self.idle_hooks: list[Callable[[], None]] = []
        self._last_idle = -float("inf")
        self._clock = clock
        self._filter = EntryFilter(self.options.filters)
        self.vehicles = [self.options.prefix + item.vehicle for item in inputs]
        self.origin = min(item.logstart for item in inputs)
        opt = self.options
        self._stop_time = float("inf") if opt.stop is None else self.origin + opt.stop
        ends = [item.end for item in inputs]
        known_end = None if None in ends else max(e for e in ends if e is not None)
        self._end: float | None = known_end
        if opt.stop is not None:
            self._end = self._stop_time if known_end is None else min(known_end, self._stop_time)
        self._begin = self.origin if opt.start is None else self.origin + opt.start
        self._commands: queue.SimpleQueue[tuple[Command, Future[Status]]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._state = State.PAUSED if opt.paused else State.PLAYING
        self._rate = opt.rate
        self._anchor_log = self._begin
        self._anchor_now = 0.0
        self._frozen = self._begin
        self._last = self._begin  # the newest time published (the position, fast)
        self._heartbeat: float | None = None
        self._schedule: Schedule | None = None
        self._next: Item | None = None
        self._pass_items = 0
        self._consumed = -float("inf")  # the newest time the pass went past
        self._counts = {vehicle: VehicleCounts() for vehicle in self.vehicles}
        self._timing = Lateness()
        self._errors: list[str] = []
        self._loops = 0
        self._dropped = [0, 0, 0]  # duplicates, before LOGSTART, late: of closed passes

    # -- other threads

    def submit(self, command: Command) -> Future[Status]:
        """Queue a command; the future gets the status after it was applied.

        The future fails with :class:`ReplayError` when the command cannot apply, or when
        the replay has ended.
        """
        future: Future[Status] = Future()
        if self._state in (State.FINISHED, State.STOPPED):
            future.set_exception(ReplayError("the replay has ended"))
            return future
        self._commands.put((command, future))
        self._clock.wake()
        return future

    def heartbeat(self, client_time: float) -> None:
        """Take a PLAYBACK_CHOKE heartbeat: the client's clock time when it sent it."""
        self._heartbeat = client_time
        self._clock.wake()

    def stop(self) -> None:
        """End the replay soon (from any thread, e.g. a signal handler)."""
        self.submit(Stop())

    def status(self) -> Status:
        """Return a snapshot of the player (from any thread)."""
        with self._lock:
            state = self._state
            position = self._position_locked()
            rate = self._rate
        counts = list(self._counts.values())
        end = None if self._end is None else self._end - self.origin
        return Status(
            state,
            position,
            position - self.origin,
            self._begin - self.origin,
            end,
            rate,
            sum(c.published for c in counts),
            sum(c.filtered for c in counts),
            self._loops,
            tuple(dict.fromkeys(self.vehicles)),
        )

    # -- position

    def _position_locked(self) -> float:
        if self._state is State.PLAYING and self._rate is not None:
            position = self._anchor_log + (self._clock.now() - self._anchor_now) * self._rate
            if self._next is not None and not self._next[LATE]:
                # Not past the entry it waits for: a choke or a slow publish holds it there.
                position = min(position, max(self._next[TIME], self._last))
            return min(position, self._stop_time)
        if self._state is State.PLAYING:
            return self._last
        return self._frozen

    def _set_anchor(self, position: float) -> None:
        self._anchor_log = position
        self._anchor_now = self._clock.now()
        self._frozen = position
        self._last = position

    def _due(self, when: float) -> float:
        assert self._rate is not None
        return self._anchor_now + (when - self._anchor_log) / self._rate

    # -- schedule

    def _open(self, at: float) -> None:
        """Start a new pass and skip to ``at`` (without publishing)."""
        self._close_schedule()
        opt = self.options
        self._schedule = Schedule(
            self.inputs, window=opt.window, dedupe=opt.dedupe, memory=opt.dedupe_memory
        )
        self._next = next(self._schedule, None)
        self._consumed = -float("inf")
        self._skip_to(at)
        self._pass_items = 0  # what the pass plays, not what it skipped

    def _skip_to(self, at: float) -> None:
        while self._next is not None and self._next[TIME] < at:
            self._advance()

    def _advance(self) -> None:
        assert self._schedule is not None
        if self._next is not None and self._next[TIME] > self._consumed:
            self._consumed = self._next[TIME]
        self._next = next(self._schedule, None)
        self._pass_items += 1

    def _close_schedule(self) -> None:
        schedule = self._schedule
        if schedule is not None:
            self._dropped[0] += schedule.duplicates
            self._dropped[1] += schedule.before_logstart
            self._dropped[2] += schedule.late
            schedule.close()
            self._schedule = None

    # -- the loop

    def run(self) -> Summary:
        """Play to the end (or until stopped) and return the summary.

        Raises:
            StorageError: an input cannot be read.
            FormatError: (``errors="raise"`` readers) an input has a malformed line; the
                message names the file and line.
        """
        started = self._clock.now()
        try:
            self._open(self._begin)
            if self.options.start is None and self._next is not None:
                self._begin = self._next[TIME]
            if self.options.db_time:
                for vehicle in dict.fromkeys(self.vehicles):
                    self._out.prepare_once(vehicle, "PLAYBACK_DB_TIME", Kind.DOUBLE)
            self._prepare_ahead(None)
            with self._lock:
                self._set_anchor(self._begin)
            self._play()
        finally:
            self._close_schedule()
            self._fail_pending()
        return self._summary(self._clock.now() - started)

    def _play(self) -> None:
        clock = self._clock
        while True:
            self._apply_commands()
            state = self._state
            if state is State.STOPPED:
                return
            if state is State.PAUSED:
                clock.wait(self._idle_deadline())
                self._idle(clock.now(), None)
                continue
            item = self._next
            if (
                self._rate is None
                and state is State.PLAYING
                and self._heartbeat is None
                and item is not None
                and item[TIME] <= self._stop_time
            ):
                self._play_fast()
                continue
            if item is None or item[TIME] > self._stop_time:
                if self._wrap():
                    continue
                with self._lock:
                    self._frozen = min(max(self._last, self._begin), self._stop_time)
                    if self._end is None and item is None:
                        self._end = self._frozen
                    self._state = State.FINISHED
                return
            if not self._filter.allows(item[KEY], item[SOURCE]):
                self._counts[self.vehicles[item[ORIGIN]]].filtered += 1
                self._advance()
                continue
            if self._choked():
                # Only a fresh heartbeat, a seek or a command ends it.
                clock.wait(self._idle_deadline())
                self._idle(clock.now(), None)
                continue
            due = None
            if self._rate is not None and not item[LATE]:
                due = self._due(item[TIME])
                now = clock.now()
                if now < due:
                    if self._out.prepares:
                        self._prepare_ahead(due)
                    self._idle(clock.now(), due)
                    now = clock.now()
                if now < due:
                    # Wake when the heartbeat turns stale too, so a choke stops the
                    # position where uPlayBack's tick would have, not at the next entry;
                    # and for the idle work, when the entry is far off.
                    deadline = min(due, self._choke_deadline(now))
                    idle_at = self._idle_deadline()
                    if idle_at is not None and idle_at < due - IDLE_SLACK:
                        deadline = min(deadline, max(idle_at, now))
                    if clock.wait(deadline) or deadline < due:
                        continue  # apply the commands (or the choke), then look again
            elif self.idle_hooks:
                self._idle(clock.now(), None)
            self._emit(item, due)

    def _wrap(self) -> bool:
        """At the end: start the next loop if looping (and the last pass played anything)."""
        if not self.options.loop or self._pass_items == 0:
            return False
        self._loops += 1
        self._open(self._begin)
        with self._lock:
            self._set_anchor(self._begin)
        self._out.new_tick()
        return True

    def _idle_deadline(self) -> float | None:
        return self._last_idle + IDLE_PERIOD if self.idle_hooks else None

    def _idle(self, now: float, due: float | None) -> None:
        """Run the idle hooks if their period is up and the next entry leaves time for them.

        With entries closer than :data:`IDLE_SLACK` for a whole :data:`IDLE_FORCE`, they run
        anyway: one late entry a second rather than a frozen display.
        """
        if not self.idle_hooks or now - self._last_idle < IDLE_PERIOD:
            return
        if due is not None and due - now < IDLE_SLACK and now - self._last_idle < IDLE_FORCE:
            return
        self._last_idle = now
        for hook in self.idle_hooks:
            hook()

    def _prepare_ahead(self, due: float | None) -> None:
        """Prepare the next entries' publishers, keeping clear of ``due``."""
        if not self._out.prepares or self._schedule is None:
            return
        upcoming = [self._next] if self._next is not None else []
        self._out.prepare_ahead((*upcoming, *self._schedule.ahead), self.vehicles, due, self._clock)

    def _choke_deadline(self, now: float) -> float:
        heartbeat = self._heartbeat
        if heartbeat is None:
            return float("inf")
        # Just past the limit: the choke starts once the heartbeat is *more* than it old.
        return now + (heartbeat + self.options.choke_time - self._clock.wall()) + 1e-6

    def _choked(self) -> bool:
        heartbeat = self._heartbeat
        if heartbeat is None and self._state is State.PLAYING:
            return False  # no client: the per-entry fast path, without the lock
        choked = heartbeat is not None and self._clock.wall() - heartbeat > self.options.choke_time
        with self._lock:
            if choked and self._state is State.PLAYING:
                self._frozen = self._position_locked()
                self._state = State.WAITING
            elif not choked and self._state is State.WAITING:
                self._state = State.PLAYING
                self._set_anchor(self._frozen)
        return choked

    def _emit(self, item: Item, due: float | None) -> None:
        """Publish one entry (after PLAYBACK_DB_TIME if it opens a tick) and move on."""
        self._publish(item, due)
        self._advance()

    def _publish(self, item: Item, due: float | None) -> None:
        """Publish one entry (after PLAYBACK_DB_TIME if it opens a tick), or count it."""
        assert self._schedule is not None
        vehicle = self.vehicles[item[ORIGIN]]
        value: float | str | bytes
        try:
            raw = item[VALUE]
            value = self._schedule.payload(item) if isinstance(raw, BinaryRef) else raw
        except StorageError as err:
            self._counts[vehicle].unplayable += 1
            if len(self._errors) < _MAX_ERRORS:
                self._errors.append(str(err))
            return
        clock = self._clock
        wall = clock.wall()
        if self.options.db_time:
            self._db_time(vehicle, item, wall)
        self._out.entry(vehicle, item, value, wall)
        if due is not None:
            self._timing.add(clock.now() - due)
        self._counts[vehicle].published += 1
        if item[TIME] > self._last:
            self._last = item[TIME]

    def _play_fast(self) -> None:
        """Publish entries back to back: playing as fast as possible, with no choke client.

        What the general loop does for each such entry, without its per-entry calls. It
        returns at a command, a heartbeat, the stop time or the end, for the general loop.
        """
        schedule = self._schedule
        assert schedule is not None
        commands = self._commands
        clock = self._clock
        wall = clock.wall
        publish = self._out.entry
        allows = self._filter.allows if self._filter.active else None
        vehicles = self.vehicles
        counts = [self._counts[v] for v in vehicles]
        published = [0] * len(vehicles)  # added to counts every 64 entries, and at the end
        stop_time = self._stop_time
        db_time = self.options.db_time
        hooks = self.idle_hooks
        last, consumed, played = self._last, self._consumed, 0
        head = self._next
        item = head
        try:
            while head is not None:
                run = schedule.take()
                for index, item in enumerate(chain((head,), run)):
                    t = item[TIME]
                    if t > stop_time or not commands.empty() or self._heartbeat is not None:
                        schedule.give_back(run[index:])
                        return
                    if t > consumed:
                        consumed = t
                    played += 1
                    if not played & 63:
                        _add_published(counts, published)
                        if hooks:
                            self._idle(clock.now(), None)
                    if allows is not None and not allows(item[KEY], item[SOURCE]):
                        counts[item[ORIGIN]].filtered += 1
                        continue
                    value = item[VALUE]
                    if isinstance(value, BinaryRef):
                        self._publish(item, None)  # the bytes are read, or the error counted
                        last = self._last
                        continue
                    at = wall()
                    origin = item[ORIGIN]
                    if db_time:
                        self._db_time(vehicles[origin], item, at)
                    publish(vehicles[origin], item, value, at)
                    published[origin] += 1
                    if t > last:
                        last = self._last = t
                head = item = next(schedule, None)
        finally:
            _add_published(counts, published)
            self._next = item
            self._consumed = consumed
            self._pass_items += played

    def _db_time(self, vehicle: str, item: Item, wall: float) -> None:
        tick_end = self._out.opens_tick(vehicle, self._clock.now())
        if tick_end is None:
            return
        value = item[TIME]
        if self._rate is not None and self._state is State.PLAYING:
            value = max(value, self._anchor_log + (tick_end - self._anchor_now) * self._rate)
        value = min(value, max(self._stop_time, item[TIME]))
        self._out.db_time(vehicle, value, wall)

    # -- the end

    def _summary(self, elapsed: float) -> Summary:
        duplicates, before, late = self._dropped
        state = self._state if self._state is State.FINISHED else State.STOPPED
        return Summary(
            state,
            dict(self._counts),
            duplicates,
            before,
            late,
            self._loops,
            elapsed,
            self._timing,
            list(self._errors),
            [
                (
                    item.name,
                    item.vehicle,
                    self.vehicles[i],
                    item.vehicle_from,
                    item.reader.truncated,
                )
                for i, item in enumerate(self.inputs)
            ],
        )


def _add_published(counts: list[VehicleCounts], published: list[int]) -> None:
    """Add the entries published since the last call to each input's counts; reset them."""
    for origin, count in enumerate(published):
        if count:
            counts[origin].published += count
            published[origin] = 0
