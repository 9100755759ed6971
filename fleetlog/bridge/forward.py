"""What crosses the bridge and what does not: echoes, duplicates, MOOS's type rule, counts.

The engine has no sockets and no Zenoh in it: the service hands it the MOOSDB's mail
(:meth:`Forwarder.from_moos`) and Zenoh's samples turned into MOOS notifications
(:meth:`Forwarder.from_zenoh`), and gives it functions to publish on Zenoh and to post into
the MOOSDB. Its rules:

* **No loops.** Zenoh does not deliver the bridge's own publications back to it (the service
  subscribes to remote origins only). The MOOSDB does deliver the bridge's posts back to it
  (it is subscribed to them): each post is remembered by name, time, source, type and a
  digest of its value, and the first matching message from the DB is dropped as its echo.
  No field of any message is changed to mark it.
* **No duplicates.** A (re)registration makes the DB re-deliver a variable's current value
  with its original time; a message equal to the last one forwarded for its variable (time,
  source and value) is dropped.
* **MOOS's type rule.** A MOOS variable keeps the type of its first write; the DB drops a
  later write of another type without a word. The engine learns each variable's type from
  the DB's mail and from its own first posts, does not post a sample of another type, counts
  it and says so once per variable on MOOS_DEBUG.
* **Nothing silent.** Whatever could not cross (no MOOSDB, no Zenoh link, too large, a type
  clash, a post the DB never echoed) is counted in :class:`BridgeStats`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fleetlog.bridge.echo import EchoFilter
from fleetlog.errors import FleetlogError
from fleetlog.moos.patterns import MoosGlob
from fleetlog.moos.protocol import DataType, Message

__all__ = ["BridgeStats", "Forwarder"]

_TYPE_NAMES = {DataType.DOUBLE: "double", DataType.STRING: "string", DataType.BINARY: "binary"}
#: names whose per-variable state is kept (types, last forwarded); beyond, it starts over
MAX_NAMES = 65536
#: plain registrations the bridge makes for variables it posts outside ``ToZenoh``
MAX_REGISTERED = 4096


@dataclass
class BridgeStats:
    """What the bridge did with what it received, in both directions."""

    #: notifications received from the MOOSDB
    from_moos: int = 0
    #: of those, published on Zenoh
    to_zenoh: int = 0
    #: the MOOSDB's echoes of the bridge's own posts, dropped
    echoes: int = 0
    #: values the MOOSDB delivered again (after a registration), dropped
    redelivered: int = 0
    #: variables the bridge receives only to know their type (outside ``ToZenoh``)
    not_selected: int = 0
    #: could not be published: no Zenoh link, or Zenoh refused
    unforwarded_to_zenoh: int = 0
    #: samples received from Zenoh (other sessions' publications of this vehicle)
    from_zenoh: int = 0
    #: of those, posted into the MOOSDB
    to_moos: int = 0
    #: outside ``FromZenoh``
    filtered: int = 0
    #: not posted: the variable has another type in the MOOSDB
    type_clashes: int = 0
    #: could not be posted: no connection to the MOOSDB
    unforwarded_to_moos: int = 0
    #: not posted: larger than the largest packet the bridge accepts
    too_large: int = 0
    #: samples whose key names no variable or whose attachment/payload was unreadable
    garbled: int = 0
    #: posts the MOOSDB never echoed back (refused for their type, or lost with the link)
    unconfirmed: int = 0
    #: packets from the MOOSDB skipped for being larger than the limit
    oversized: int = 0
    #: samples from Zenoh lost to an unexpected error in the receiving thread (a bug)
    rx_errors: int = 0
    #: successful connections to the MOOSDB, and losses of every Zenoh link
    moos_connections: int = 0
    zenoh_losses: int = 0

    def as_dict(self) -> dict[str, int]:
        """Return the counters as a dict."""
        return dict(self.__dict__)


class _Selection:
    """MOOS globs with a per-name verdict cache."""

    def __init__(self, patterns: Sequence[str]) -> None:
        self.everything = "*" in patterns
        self._globs = [MoosGlob(p) for p in patterns]
        self._verdicts: dict[str, bool] = {}

    def __call__(self, name: str) -> bool:
        verdict = self._verdicts.get(name)
        if verdict is None:
            verdict = self.everything or any(g.matches(name) for g in self._globs)
            if len(self._verdicts) > MAX_NAMES:
                self._verdicts.clear()
            self._verdicts[name] = verdict
        return verdict


class Forwarder:
    """The bridge's rules for one vehicle.

    Args:
        name: the bridge's MOOS name (the source of its own posts).
        vehicle: the vehicle (MOOS community) bridged.
        to_zenoh: MOOS globs of the variables forwarded to Zenoh.
        from_zenoh: MOOS globs of the variables posted into the MOOSDB.
        publish: publishes a notification on Zenoh (may raise FleetlogError).
        post: queues notifications for the MOOSDB; False when not connected.
        subscribe: registers the bridge for one variable at the MOOSDB.
        clock: the wall clock.
        max_post: the largest message the bridge posts, in bytes.
        on_say: called with each line the bridge reports (for the terminal).
    """

    def __init__(
        self,
        *,
        name: str,
        vehicle: str,
        to_zenoh: Sequence[str],
        from_zenoh: Sequence[str],
        publish: Callable[[Message], None],
        post: Callable[[list[Message]], bool],
        subscribe: Callable[[str], None],
        clock: Callable[[], float],
        max_post: int,
        on_say: Callable[[str], None] = lambda text: None,
    ) -> None:
        self.name = name
        self.vehicle = vehicle
        self._publish = publish
        self._post = post
        self._subscribe = subscribe
        self._clock = clock
        self.max_post = max_post
        self._on_say = on_say
        self.stats = BridgeStats()
        self.echo = EchoFilter()
        self._types: dict[str, str] = {}
        self._last: dict[str, tuple[float, str, float, bytes]] = {}
        self._to = _Selection(to_zenoh)
        self._from = _Selection(from_zenoh)
        self._registered: set[str] = set()
        self._registered_full = False
        self._clashes_said: set[str] = set()
        #: set by the service: whether Zenoh has a link and the MOOSDB a connection
        self.zenoh_up = True
        self.moos_up = False
        #: names the bridge published on Zenoh and posted into the MOOSDB (for its status)
        self.published: set[str] = set()
        self.last_error = ""

    # ---------------------------------------------------------------------------------------
    # MOOS -> Zenoh (the hot path)

    def from_moos(self, messages: list[Message]) -> None:
        """Forward the DB's notifications to Zenoh, minus echoes and re-deliveries."""
        stats = self.stats
        types = self._types
        echo = self.echo
        last = self._last
        selected = self._to
        publish = self._publish
        for m in messages:
            if m.msg_type != "N":
                continue  # server replies and other control messages
            stats.from_moos += 1
            name = m.key
            if types.get(name) != m.data_type:
                self._learn(name, m.data_type)
            if echo and echo.take(m):
                stats.echoes += 1
                continue
            ident = (m.time, m.source, m.double, m.string)
            if last.get(name) == ident:
                stats.redelivered += 1
                continue
            if len(last) > MAX_NAMES:
                last.clear()
            last[name] = ident
            if not (selected.everything or selected(name)):
                stats.not_selected += 1
                continue
            if not self.zenoh_up:
                stats.unforwarded_to_zenoh += 1
                continue
            try:
                publish(m)
            except FleetlogError as err:
                stats.unforwarded_to_zenoh += 1
                self._failed(str(err))
            else:
                stats.to_zenoh += 1

    def _learn(self, name: str, dtype: str) -> None:
        if len(self._types) > MAX_NAMES:
            self._types.clear()
        self._types[name] = dtype

    def _failed(self, error: str) -> None:
        if error != self.last_error:
            self.last_error = error
            self._on_say(f"could not forward to Zenoh: {error}")

    # ---------------------------------------------------------------------------------------
    # Zenoh -> MOOS

    def from_zenoh(self, items: Sequence[tuple[Message | None, bool]]) -> None:
        """Post Zenoh's samples into the MOOSDB under their original source and time."""
        stats = self.stats
        types = self._types
        now = self._clock()
        out: list[Message] = []
        for message, garbled in items:
            stats.from_zenoh += 1
            if garbled:
                stats.garbled += 1
            if message is None:
                continue
            name = message.key
            if not self._from(name):
                stats.filtered += 1
                continue
            known = types.get(name)
            if known is not None and known != message.data_type:
                stats.type_clashes += 1
                self._clash(message, known)
                continue
            if not self.moos_up:
                stats.unforwarded_to_moos += 1
                continue
            # size() encodes four texts: only a large value can come near the limit
            if len(message.string) + 4096 > self.max_post and message.size() > self.max_post:
                stats.too_large += 1
                continue
            if known is None:
                self._learn(name, message.data_type)
            if not self._to.everything and name not in self._registered:
                # Outside a wildcard registration: register, so the DB's echo of this post
                # (and the variable's type) reaches the bridge. A flood of new names from a
                # peer must not grow the registrations without end: past the limit a post
                # goes unregistered (no echo comes back; it is counted as unconfirmed).
                if len(self._registered) < MAX_REGISTERED:
                    self._registered.add(name)
                    self._subscribe(name)
                elif not self._registered_full:
                    self._registered_full = True
                    self.say(
                        f"more than {MAX_REGISTERED} variables posted from Zenoh outside "
                        "ToZenoh: later ones are posted without registering for them"
                    )
            stats.unconfirmed += self.echo.expect(message, now)
            out.append(message)
        if out:
            if self._post(out):
                stats.to_moos += len(out)
            else:
                stats.unforwarded_to_moos += len(out)
                for message in out:
                    self.echo.take(message)

    def _clash(self, message: Message, known: str) -> None:
        name = message.key
        if name in self._clashes_said or len(self._clashes_said) >= 1024:
            return
        self._clashes_said.add(name)
        have = _TYPE_NAMES.get(known, known)
        got = _TYPE_NAMES.get(message.data_type, message.data_type)
        self.say(
            f"{name} is a {have} in the MOOSDB: a {got} from {message.source or '?'} was not "
            "posted (MOOS keeps a variable's first type); further ones are counted"
        )

    # ---------------------------------------------------------------------------------------
    # The bridge's own posts

    def say(self, text: str) -> None:
        """Report on MOOS_DEBUG, in the MOOSDB and on Zenoh, and to the terminal."""
        self._on_say(text)
        self.own("MOOS_DEBUG", text)

    def own(self, name: str, value: str) -> None:
        """Post one of the bridge's own messages into the MOOSDB and publish it on Zenoh.

        Posted directly to both sides (its echo from the DB is dropped like any other), so
        it reaches Zenoh while the MOOSDB is away and the MOOSDB while Zenoh is.
        """
        message = Message(
            "N",
            DataType.STRING,
            name,
            self._clock(),
            string=value.encode("utf-8", "surrogateescape"),
            source=self.name,
            community=self.vehicle,
        )
        self.published.add(name)
        if self.moos_up and self._types.get(name, DataType.STRING) == DataType.STRING:
            self._learn(name, DataType.STRING)
            self.echo.expect(message, self._clock())
            if not self._post([message]):
                self.echo.take(message)
        if self.zenoh_up:
            try:
                self._publish(message)
            except FleetlogError as err:
                self._failed(str(err))

    # ---------------------------------------------------------------------------------------
    # Timers and connection changes

    def tick(self) -> None:
        """Count posts whose echo is overdue (called about once a second)."""
        self.stats.unconfirmed += self.echo.expire(self._clock())

    def moos_lost(self) -> None:
        """The MOOSDB connection ended: posts still waiting for their echo are unconfirmed."""
        self.moos_up = False
        self.stats.unconfirmed += self.echo.clear()

    def moos_connected(self) -> None:
        """A new connection: the DB may be a new one, whose types start afresh."""
        self.moos_up = True
        self.stats.moos_connections += 1
        self._types.clear()
        # the client renews its registrations itself: ``_registered`` stays as it is
