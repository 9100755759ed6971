"""Which vehicles are up, found the same way every time.

A query sent right after a Zenoh session opens reaches only the peers connected by then. With
embedded peers and multicast scouting (fleetlog's default), ``zenoh.open`` returns once the
first peer answers the scout, and the others connect a few milliseconds later: a plain query
then saw 1 of 3 vehicles in 4 of 10 runs. So every shore command first *watches* the
recorder and log-server liveliness tokens (subscribers with history: tokens declared before
them arrive too) and proceeds when

* every vehicle it expects is seen (``--expect``, or the vehicle a command names), or
* without expectations, once at least one vehicle is seen and neither a new token nor a new
  Zenoh peer appeared for a quiet period (:data:`QUIET`): the fleet has stopped growing;
* in any case after ``wait`` seconds, the cap; with no vehicle in sight a command waits that
  long before it says none is up.

No fixed sleep: a command that names one vehicle proceeds as soon as that vehicle's token
arrives, typically within milliseconds. The watch stays on while the command runs, so a
vehicle that stops meanwhile is known to be gone when its queries go unanswered.

:class:`Settle` is the decision alone (no Zenoh, no clock of its own), tested with a fake
clock; :class:`Discovery` runs it on a :class:`~fleetlog.transport.services.TokenWatch`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

from fleetlog.errors import FormatError
from fleetlog.transport.queries import ZenohSession
from fleetlog.transport.services import TokenWatch
from fleetlog.wire.keys import fleet_service_selector, parse_service_key
from fleetlog.wire.query import RECORDER_TOKEN, SERVE_TOKEN

__all__ = ["QUIET", "REPLAY_TOKEN", "SERVICES", "WAIT", "Discovery", "FleetView", "Settle"]

#: seconds without a new token or peer after which the fleet is taken as complete
QUIET = 0.3
#: seconds a command waits for the fleet at most (``--wait``)
WAIT = 3.0
#: the liveliness tokens that make a vehicle "up"
SERVICES = (RECORDER_TOKEN, SERVE_TOKEN)
#: the liveliness token of a running replay, one per vehicle it plays
REPLAY_TOKEN = "replay"
#: how often the peers are looked at while nothing else happens
_PEER_POLL = 0.02


@dataclass(frozen=True)
class FleetView:
    """The vehicles up when discovery settled, and why it stopped waiting.

    Attributes:
        vehicles: vehicle → the tokens it holds (``recorder``, ``serve``).
        expected: the vehicles the command asked for.
        reason: ``expected`` (all of them seen), ``quiet`` (the fleet stopped growing) or
            ``wait`` (the cap ran out).
        waited: seconds spent waiting.
    """

    vehicles: Mapping[str, frozenset[str]]
    expected: tuple[str, ...] = ()
    reason: str = "quiet"
    waited: float = 0.0

    @property
    def names(self) -> list[str]:
        """The vehicles up, sorted."""
        return sorted(self.vehicles)

    @property
    def missing(self) -> list[str]:
        """The expected vehicles that are not up."""
        return [v for v in self.expected if v not in self.vehicles]

    def describe(self) -> str:
        """One sentence: who answered, who is missing, how long it took."""
        up = ", ".join(self.names) if self.vehicles else "none"
        text = f"{len(self.vehicles)} vehicle(s) up: {up} (found in {self.waited:.2f} s)"
        if self.missing:
            text += f"; not up after {self.waited:.1f} s: {', '.join(self.missing)}"
        return text


@dataclass
class Settle:
    """Decides when discovery has waited long enough (see the module docstring).

    Args:
        start: when the watch began (the clock's seconds).
        expect: the vehicles to wait for.
        quiet: seconds without a new token or peer that end the wait without expectations.
        wait: seconds after ``start`` that end it in any case.
    """

    start: float
    expect: frozenset[str] = frozenset()
    quiet: float = QUIET
    wait: float = WAIT
    last_news: float = field(init=False)

    def __post_init__(self) -> None:
        self.last_news = self.start

    def news(self, now: float) -> None:
        """A new token or a new peer appeared."""
        self.last_news = max(self.last_news, now)

    def verdict(self, now: float, vehicles: Iterable[str]) -> str | None:
        """Return why to stop now (``expected``, ``quiet``, ``wait``), or None to go on."""
        up = set(vehicles)
        if self.expect and self.expect <= up:
            return "expected"
        if now - self.start >= self.wait:
            return "wait"
        if not self.expect and up and now - self.last_news >= self.quiet:
            return "quiet"
        return None

    def remaining(self, now: float) -> float:
        """Seconds until time alone could change the verdict."""
        left = self.start + self.wait - now
        if not self.expect:
            left = min(left, self.last_news + self.quiet - now)
        return max(0.0, left)


class Discovery:
    """Watches a fleet's recorder and log-server tokens for as long as it is open.

    Args:
        session: an open Zenoh session (not closed here).
        root: the key root.
        quiet: see :class:`Settle`.
        clock: monotonic seconds (tests pass a fake one).
        services: the tokens that count (``recorder`` and ``serve``: a vehicle is up;
            ``replay``: a replay plays it).

    Raises:
        TransportError: the liveliness subscription failed.
    """

    def __init__(
        self,
        session: ZenohSession,
        root: str,
        *,
        quiet: float = QUIET,
        clock: Callable[[], float] = time.monotonic,
        services: tuple[str, ...] = SERVICES,
    ) -> None:
        self.root = root
        self.quiet = quiet
        self.services = services
        self._clock = clock
        self._started = clock()
        self._tokens: dict[str, set[str]] = {}
        self._peers: frozenset[str] = frozenset()
        self._watch = TokenWatch(session, [fleet_service_selector(root, s) for s in services])
        self.settled: FleetView | None = None

    def close(self) -> None:
        """Stop watching."""
        self._watch.close()

    def _apply(self, key: str, alive: bool) -> bool:
        """Take one token change; return True if it is a vehicle or service not seen before."""
        try:
            vehicle, parts = parse_service_key(self.root, key)
        except FormatError:
            return False
        if len(parts) != 1 or parts[0] not in self.services:
            return False
        services = self._tokens.get(vehicle)
        if alive:
            if services is None:
                services = self._tokens[vehicle] = set()
            new = parts[0] not in services
            services.add(parts[0])
            return new
        if services is not None:
            services.discard(parts[0])
            if not services:
                del self._tokens[vehicle]
        return False

    def _pump(self, timeout: float) -> bool:
        """Take the changes that arrive within ``timeout``; return True on any news."""
        news = False
        change = self._watch.next_change(timeout)
        while change is not None:
            news |= self._apply(*change)
            change = self._watch.next_change(0)
        peers = self._watch.neighbours()
        if peers - self._peers:
            news = True
        self._peers = peers
        return news

    def current(self) -> dict[str, frozenset[str]]:
        """Return the vehicles up now (the changes received so far applied)."""
        self._pump(0)
        return {v: frozenset(s) for v, s in self._tokens.items()}

    def wait(self, expect: Iterable[str] = (), wait: float = WAIT) -> FleetView:
        """Wait until the fleet is known (see the module docstring) and return it.

        The wait counts from when the watch began (the client opened), so the time spent
        opening and preparing is not waited again.

        Args:
            expect: vehicles to wait for; the wait ends as soon as all are up.
            wait: seconds at most.
        """
        expected = tuple(dict.fromkeys(expect))
        settle = Settle(self._started, frozenset(expected), self.quiet, wait)
        while True:
            now = self._clock()
            if self._pump(0):
                settle.news(now)
            reason = settle.verdict(now, self._tokens)
            if reason is not None:
                break
            if self._pump(min(settle.remaining(now), _PEER_POLL)):
                settle.news(self._clock())
        view = FleetView(
            {v: frozenset(s) for v, s in self._tokens.items()},
            expected,
            reason,
            now - self._started,
        )
        self.settled = view
        return view
