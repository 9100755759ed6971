"""What the player publishes, uPlayBack's way (MOOS_FORMAT.md §8).

* each message keeps its variable and source (split into source, aux and community), its time
  is the replay clock's wall time, and its original absolute time travels with it;
* ``PLAYBACK_DB_TIME`` (a double, absolute log time, source ``uPlayback``) is posted first in
  every 10 ms tick that posts something, to each vehicle that gets something in it (its value,
  a position, is the player's: :meth:`Output.opens_tick` says when one is due);
* each vehicle, variable and type is prepared (its publisher declared) once, ahead of its
  first publication, while the player has time to spare.

All of it runs in the player's thread.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Protocol

from fleetlog.moos.alog import split_source
from fleetlog.replayer.clock import Clock
from fleetlog.replayer.items import KEY, ORIGIN, PAYLOAD, SOURCE, TIME, VALUE, Item
from fleetlog.wire.message import Kind, MoosMessage, encode_value, new_message

__all__ = ["DB_TIME_SOURCE", "TICK", "Output", "Prepare", "Publish", "Sender", "Senders"]

#: uPlayBack's GUI timer period: at most one PLAYBACK_DB_TIME per vehicle per tick.
TICK = 0.01
#: The source of PLAYBACK_DB_TIME (uPlayBack's client name).
DB_TIME_SOURCE = "uPlayback"

#: How the player publishes: ``publish(vehicle, message)``.
Publish = Callable[[str, MoosMessage], None]
#: ``prepare(vehicle, variable, kind)``: get ready to publish it (declare its publisher), so
#: the first publication of a variable is not late by the declaration's cost.
Prepare = Callable[[str, str, Kind], None]


class Sender(Protocol):
    """Publishes one variable of one vehicle with one origin (a replay link makes them)."""

    def send(self, payload: bytes, time: float, original_time: float) -> None:
        """Publish a value's payload with its time (the replay clock's) and recorded time."""


#: ``senders(vehicle, variable, kind, source, aux, community)``: a :class:`Sender` for the
#: entries with this origin. With it the player publishes an entry as its payload and two
#: times (the rest is held by the sender) instead of a whole :class:`MoosMessage`.
Senders = Callable[[str, str, Kind, str, str, str], Sender]
#: Slack kept before a due entry when preparing the ones after it, seconds.
_PREPARE_SLACK = 0.002
#: Bound on the memo sets and caches (cleared when full: a re-prepare or re-split is cheap).
_CACHE_LIMIT = 65536


class Output:
    """Publishes the player's entries and PLAYBACK_DB_TIME, and prepares their publishers.

    Args:
        publish: called for every message, with the vehicle to publish under.
        prepare: called once per vehicle, variable and type before its first publication;
            None: nothing to prepare.
        senders: makes the senders that publish entries (``publish`` then only posts
            PLAYBACK_DB_TIME); None: entries go to ``publish`` as messages.
    """

    def __init__(
        self, publish: Publish, prepare: Prepare | None = None, senders: Senders | None = None
    ) -> None:
        self._publish = publish
        self._prepare = prepare
        self._senders = senders
        self._by_origin: dict[tuple[int, str, str, Kind], Sender] = {}
        self._prepared: set[tuple[str, str, Kind]] = set()
        self._sources: dict[str, tuple[str, str, str]] = {}
        self._slot = -1
        self._slot_vehicles: set[str] = set()

    @property
    def prepares(self) -> bool:
        """Whether there is anything to prepare."""
        return self._prepare is not None

    def entry(self, vehicle: str, item: Item, value: float | str | bytes, wall: float) -> None:
        """Publish an entry (its payload read) with the replay clock's wall time."""
        if self._senders is not None:
            # The schedule made most payloads with its columns; the rest are made here.
            payload = item[PAYLOAD]
            kind: Kind
            if isinstance(value, str):
                kind = Kind.STRING
                if payload is None:
                    payload = value.encode("utf-8", "surrogateescape")
            elif payload is not None and isinstance(value, float):
                kind = Kind.DOUBLE
            else:
                kind, payload = encode_value(value)
            sender = self._by_origin.get((item[ORIGIN], item[KEY], item[SOURCE], kind))
            if sender is None:
                sender = self._sender(vehicle, item, kind)
            sender.send(payload, wall, item[TIME])
            return
        source, aux, community = self._split(item[SOURCE])
        # new_message: the frozen MoosMessage without its __init__'s seven __setattr__ calls
        self._publish(
            vehicle, new_message(item[KEY], value, wall, source, aux, community, item[TIME])
        )

    def _sender(self, vehicle: str, item: Item, kind: Kind) -> Sender:
        assert self._senders is not None
        source, aux, community = self._split(item[SOURCE])
        # A live process's community is its vehicle's: so is a replayed one's without "@".
        sender = self._senders(vehicle, item[KEY], kind, source, aux, community or vehicle)
        if len(self._by_origin) > _CACHE_LIMIT:
            self._by_origin.clear()
        self._by_origin[(item[ORIGIN], item[KEY], item[SOURCE], kind)] = sender
        return sender

    def _split(self, field: str) -> tuple[str, str, str]:
        parts = self._sources.get(field)
        if parts is None:
            parts = split_source(field)
            if len(self._sources) > _CACHE_LIMIT:
                self._sources.clear()
            self._sources[field] = parts
        return parts

    def opens_tick(self, vehicle: str, now: float) -> float | None:
        """Return the tick's end (clock time) if ``vehicle`` gets nothing in it yet, else None.

        The caller then posts :meth:`db_time` before the entry.
        """
        slot = int(now / TICK)
        if slot != self._slot:
            self._slot = slot
            self._slot_vehicles.clear()
        if vehicle in self._slot_vehicles:
            return None
        self._slot_vehicles.add(vehicle)
        return (slot + 1) * TICK

    def new_tick(self) -> None:
        """Let the next entry open a tick (after a resume, seek or loop)."""
        self._slot = -1

    def db_time(self, vehicle: str, value: float, wall: float) -> None:
        """Post PLAYBACK_DB_TIME = ``value`` (absolute log time) to ``vehicle``."""
        self._publish(vehicle, MoosMessage("PLAYBACK_DB_TIME", value, wall, DB_TIME_SOURCE))

    def prepare_once(self, vehicle: str, name: str, kind: Kind) -> None:
        """Prepare a vehicle's variable of this type, unless that was done already."""
        if self._prepare is None:
            return
        sig = (vehicle, name, kind)
        if sig not in self._prepared:
            if len(self._prepared) > _CACHE_LIMIT:
                self._prepared.clear()
            self._prepared.add(sig)
            self._prepare(vehicle, name, kind)

    def prepare_ahead(
        self, items: Iterable[Item], vehicles: Sequence[str], due: float | None, clock: Clock
    ) -> None:
        """Prepare the coming entries' publishers, keeping clear of ``due`` (clock time)."""
        if self._prepare is None:
            return
        for item in items:
            if due is not None and clock.now() > due - _PREPARE_SLACK:
                return
            value = item[VALUE]
            kind = (
                Kind.DOUBLE
                if isinstance(value, float)
                else Kind.STRING
                if isinstance(value, str)
                else Kind.BINARY
            )
            self.prepare_once(vehicles[item[ORIGIN]], item[KEY], kind)
