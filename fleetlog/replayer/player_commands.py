"""How the player's commands move it: pause, resume, stop, rate, seek and step.

:class:`PlayerCommands` is a mixin of :class:`fleetlog.replayer.engine.Player`: the commands
are queued by any thread (:meth:`Player.submit`) and applied here, in the player's thread,
between two entries. Every change of position or rate re-anchors the clock, so the schedule
never drifts; a seek behind what the pass went past starts a new pass.
"""

from __future__ import annotations

import queue
import threading
from concurrent.futures import Future

from fleetlog.errors import ReplayError
from fleetlog.replayer.control import (
    Command,
    Pause,
    Resume,
    Seek,
    SetRate,
    Step,
    Stop,
    Toggle,
    check_rate,
    next_rate,
)
from fleetlog.replayer.filters import EntryFilter
from fleetlog.replayer.items import KEY, ORIGIN, SOURCE, TIME, Item
from fleetlog.replayer.output import Output
from fleetlog.replayer.report import State, Status, VehicleCounts

__all__ = ["PlayerCommands"]


class PlayerCommands:
    """The Player's command half (a mixin: the Player sets the attributes below)."""

    origin: float
    vehicles: list[str]
    _commands: queue.SimpleQueue[tuple[Command, Future[Status]]]
    _lock: threading.Lock
    _state: State
    _rate: float | None
    _frozen: float
    _last: float
    _begin: float
    _end: float | None
    _stop_time: float
    _consumed: float
    _heartbeat: float | None
    _next: Item | None
    _out: Output
    _filter: EntryFilter
    _counts: dict[str, VehicleCounts]

    def status(self) -> Status:
        """Return a snapshot of the player (:meth:`Player.status`)."""
        raise NotImplementedError

    def _position_locked(self) -> float:
        raise NotImplementedError

    def _set_anchor(self, position: float) -> None:
        raise NotImplementedError

    def _open(self, at: float) -> None:
        raise NotImplementedError

    def _skip_to(self, at: float) -> None:
        raise NotImplementedError

    def _advance(self) -> None:
        raise NotImplementedError

    def _emit(self, item: Item, due: float | None) -> None:
        raise NotImplementedError

    def _apply_commands(self) -> None:
        if self._commands.empty():  # the common case, checked without an exception
            return
        while True:
            try:
                command, future = self._commands.get_nowait()
            except queue.Empty:
                return
            if not future.set_running_or_notify_cancel():
                continue
            try:
                self._apply(command)
            except ReplayError as err:
                future.set_exception(err)
            else:
                future.set_result(self.status())

    def _fail_pending(self) -> None:
        while True:
            try:
                _, future = self._commands.get_nowait()
            except queue.Empty:
                return
            if future.set_running_or_notify_cancel():
                future.set_exception(ReplayError("the replay has ended"))

    def _pause(self) -> None:
        with self._lock:
            if self._state in (State.PLAYING, State.WAITING):
                self._frozen = self._position_locked()
                self._state = State.PAUSED

    def _resume(self) -> None:
        with self._lock:
            if self._state is State.PAUSED:
                self._state = State.PLAYING
                self._set_anchor(self._frozen)
        self._out.new_tick()

    def _apply(self, command: Command) -> None:
        if isinstance(command, Pause):
            self._pause()
        elif isinstance(command, Resume):
            self._resume()
        elif isinstance(command, Toggle):
            if self._state is State.PAUSED:
                self._resume()
            else:
                self._pause()
        elif isinstance(command, Stop):
            with self._lock:
                self._frozen = self._position_locked()
                self._state = State.STOPPED
        elif isinstance(command, SetRate):
            self._set_rate(command)
        elif isinstance(command, Seek):
            self._seek(command)
        elif isinstance(command, Step):
            self._step(command)

    def _set_rate(self, command: SetRate) -> None:
        if command.steps:
            rate = next_rate(self._rate, command.steps)
        else:
            rate = None if command.rate is None else check_rate(command.rate)
        with self._lock:
            position = self._position_locked()
            self._rate = rate
            self._set_anchor(position)

    def _seek(self, command: Seek) -> None:
        with self._lock:
            here = self._position_locked()
        target = self.origin + command.to if command.to is not None else here + (command.by or 0.0)
        upper = self._stop_time if self._end is None else self._end
        target = min(max(target, self._begin), upper)
        if target <= self._consumed:
            # The pass went past entries at or after the target: start a new one.
            self._open(target)
        else:
            self._skip_to(target)
        self._heartbeat = None  # GotoTime resets the choke state (§8.4)
        self._out.new_tick()
        with self._lock:
            if self._state is State.WAITING:
                self._state = State.PLAYING
            self._set_anchor(target)

    def _step(self, command: Step) -> None:
        self._pause()
        with self._lock:
            position = self._frozen
        if command.seconds is not None:
            target = min(position + command.seconds, self._stop_time)
            while (item := self._next) is not None and item[TIME] <= target:
                self._step_one(item)
            position = max(target, self._last)
        else:
            left = command.entries
            while left and (item := self._next) is not None and item[TIME] <= self._stop_time:
                left -= self._step_one(item)
            position = max(position, self._last)
        with self._lock:
            self._frozen = position
            self._last = position

    def _step_one(self, item: Item) -> int:
        """Publish (or filter out) one entry while stepping; return 1 if it was published."""
        if not self._filter.allows(item[KEY], item[SOURCE]):
            self._counts[self.vehicles[item[ORIGIN]]].filtered += 1
            self._advance()
            return 0
        before = self._counts[self.vehicles[item[ORIGIN]]].published
        self._emit(item, None)
        return self._counts[self.vehicles[item[ORIGIN]]].published - before
