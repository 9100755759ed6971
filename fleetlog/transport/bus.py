"""MOOS messages over a Zenoh session: publish, subscribe, decode (docs/wire.md).

Everything fleetlog publishes that someone may log uses BLOCK congestion control and reliable
delivery: the default DROP lost most samples at full speed on a 2-core machine. A publisher
that must never stall uses DROP with zenoh-ext's sample-miss detection, and the recorder counts
what it lost (:class:`MissCounter`).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import zenoh
import zenoh.ext

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import NAMES_CACHED
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.fields import clean_name, clean_origin, clean_value, time_ok
from fleetlog.wire.message import (
    ENCODINGS,
    Kind,
    MoosMessage,
    attachment_fields,
    decode_value,
    kind_of_encoding,
    new_message,
)

__all__ = [
    "DOUBLE_ENCODING",
    "MISS_HEARTBEAT",
    "STRING_ENCODING",
    "Incoming",
    "MissCounter",
    "SampleDecoder",
    "declare_fifo_subscriber",
    "heartbeat_keys",
    "zenoh_time",
]

#: seconds between a DROP publisher's heartbeats (its last sequence number): how soon a loss
#: at the end of a burst, which no later sample reveals, can be counted
MISS_HEARTBEAT = 1.0

_ENCODING_OBJECTS: dict[Kind, zenoh.Encoding] = {k: zenoh.Encoding(v) for k, v in ENCODINGS.items()}
# Comparing a sample's encoding with these costs a third of turning it into text.
_DOUBLE_ENCODING = _ENCODING_OBJECTS[Kind.DOUBLE]
_STRING_ENCODING = _ENCODING_OBJECTS[Kind.STRING]
#: the encodings of doubles and strings (``sample.encoding ==`` one of them: the fast lane)
DOUBLE_ENCODING = _DOUBLE_ENCODING
STRING_ENCODING = _STRING_ENCODING


def zenoh_time(sample: zenoh.Sample) -> float | None:
    """Return a sample's Zenoh timestamp as seconds since the epoch, if it has one."""
    stamp = sample.timestamp
    if stamp is None:
        return None
    return stamp.get_time().timestamp()


@dataclass(frozen=True, slots=True)
class Incoming:
    """A received sample turned into a MOOS message.

    Attributes:
        key: the sample's key expression text.
        message: the decoded message; its ``time`` is the publisher's time when the
            attachment carried one, else the Zenoh timestamp, else the receive time.
        stamped: True when the time came from the publisher's attachment.
        garbled: True when the payload did not fit its declared encoding or the
            attachment was unreadable; the value was still kept.
    """

    key: str
    message: MoosMessage
    stamped: bool
    garbled: bool


class SampleDecoder:
    """Turns Zenoh samples under one vehicle's ``var/`` prefix into MOOS messages.

    Every field is checked here, where samples enter, by the rule of
    :mod:`fleetlog.wire.fields`: what a log line could not hold unchanged is escaped and the
    sample is marked garbled. Per-key and per-origin work (unescaping and checking the
    variable name, checking source, aux and community) is cached, because the same keys and
    origins repeat at tens of thousands of samples a second.
    """

    def __init__(self, var_prefix: str, clock: Callable[[], float] = time.time) -> None:
        self._prefix = var_prefix
        self._names: dict[str, str | None] = {}
        #: keys whose name had to be escaped (their samples are garbled)
        self._escaped: set[str] = set()
        self._origins: dict[tuple[str, str, str], tuple[str, str, str, bool]] = {}
        self._clock = clock

    def name_of(self, key: str) -> str | None:
        """Return the MOOS name of a variable key, or None if the key is not one."""
        try:
            return self._names[key]
        except KeyError:
            pass
        from fleetlog.moos.patterns import chunk_to_name

        name: str | None = None
        if key.startswith(self._prefix):
            chunk = key[len(self._prefix) :]
            if chunk and "/" not in chunk:
                try:
                    name = chunk_to_name(chunk)
                except FormatError:
                    name = None
        if len(self._names) > NAMES_CACHED:
            self._names.clear()
            self._escaped.clear()
        if name is not None:
            name, escaped = clean_name(name)
            if escaped:
                self._escaped.add(key)
        self._names[key] = name
        return name

    def _origin(self, source: str, aux: str, community: str) -> tuple[str, str, str, bool]:
        ident = (source, aux, community)
        origin = self._origins.get(ident)
        if origin is None:
            origin = clean_origin(source, aux, community)
            if len(self._origins) > 4096:
                self._origins.clear()
            self._origins[ident] = origin
        return origin

    def plain_name(self, key: str) -> str | None:
        """Return the MOOS name of a variable key whose name needed no escaping, else None."""
        name = self.name_of(key)
        if name is None or key in self._escaped:
            return None
        return name

    def plain_origin(self, attachment: bytes) -> tuple[str, str, str] | None:
        """Return an attachment's ``(source, aux, community)`` if they need no escaping.

        None when the attachment is not readable, carries an original (replay) time, or
        has a field that had to be escaped: its samples go the general way (:meth:`decode`).
        The answer depends only on ``attachment[8:]`` (the time comes first).
        """
        try:
            _, source, aux, community, original = attachment_fields(attachment)
        except FormatError:
            return None
        if original is not None:
            return None
        source, aux, community, escaped = self._origin(source, aux, community)
        return None if escaped else (source, aux, community)

    def decode(self, sample: zenoh.Sample) -> Incoming | None:
        """Decode a sample; None when its key is not a variable key of this vehicle."""
        # The recorder's hot path: one call per sample, so the common case (a fleetlog
        # double with an attachment) takes the shortest way through.
        key = str(sample.key_expr)
        try:
            name = self._names[key]
        except KeyError:
            name = self.name_of(key)
        if name is None:
            return None
        encoding = sample.encoding
        if encoding == _DOUBLE_ENCODING:
            kind: Kind | None = Kind.DOUBLE
        elif encoding == _STRING_ENCODING:
            kind = Kind.STRING
        else:
            kind = kind_of_encoding(str(encoding))
        attachment = sample.attachment
        return self._build(
            key,
            name,
            sample.payload.to_bytes(),
            kind,
            None if attachment is None else attachment.to_bytes(),
            sample,
        )

    def decode_parts(
        self, key: str, payload: bytes, encoding: str, attachment: bytes | None
    ) -> Incoming | None:
        """Decode a sample given as its parts (a sample without a Zenoh timestamp).

        What :meth:`decode` does, for callers (and fuzzers) that hold no ``zenoh.Sample``.
        """
        name = self.name_of(key)
        if name is None:
            return None
        return self._build(key, name, payload, kind_of_encoding(encoding), attachment, None)

    def _build(
        self,
        key: str,
        name: str,
        payload: bytes,
        kind: Kind | None,
        attachment: bytes | None,
        sample: zenoh.Sample | None,
    ) -> Incoming:
        value: float | str | bytes
        if kind is Kind.DOUBLE:
            try:
                value = float(payload)
                garbled = False
            except ValueError:
                _, value, garbled = decode_value(payload, Kind.DOUBLE)
        else:
            _, value, garbled = decode_value(payload, kind)
        if type(value) is str and "\n" in value:
            value, forged = clean_value(value)
            garbled = garbled or forged
        if self._escaped and key in self._escaped:
            garbled = True
        if attachment is not None:
            try:
                when, source, aux, community, original = attachment_fields(attachment)
            except FormatError:
                garbled = True
            else:
                source, aux, community, escaped = self._origin(source, aux, community)
                if original is not None and not time_ok(original):
                    original = None
                    escaped = True
                if time_ok(when):
                    msg = new_message(name, value, when, source, aux, community, original)
                    return _new_incoming(key, msg, True, garbled or escaped)
                # No usable time of its own: the Zenoh timestamp or the arrival time.
                msg = new_message(
                    name, value, self._stamp(sample), source, aux, community, original
                )
                return _new_incoming(key, msg, False, True)
        return _new_incoming(key, MoosMessage(name, value, self._stamp(sample)), False, garbled)

    def _stamp(self, sample: zenoh.Sample | None) -> float:
        stamp = None if sample is None else zenoh_time(sample)
        return self._clock() if stamp is None else stamp


_incoming_setters = tuple(
    Incoming.__dict__[f].__set__ for f in ("key", "message", "stamped", "garbled")
)


def _new_incoming(key: str, message: MoosMessage, stamped: bool, garbled: bool) -> Incoming:
    """``Incoming(key, message, stamped, garbled)`` without the frozen ``__init__``'s cost."""
    incoming = object.__new__(Incoming)
    s_key, s_message, s_stamped, s_garbled = _incoming_setters
    s_key(incoming, key)
    s_message(incoming, message)
    s_stamped(incoming, stamped)
    s_garbled(incoming, garbled)
    return incoming


def matching(pub: zenoh.Publisher) -> bool:
    """Whether a subscriber matches a publisher's key right now.

    zenoh's stub says ``matching_status`` is a bool, but at run time it is a MatchingStatus,
    which is always truthy: its ``matching`` field is the answer.
    """
    status: Any = pub.matching_status
    return bool(getattr(status, "matching", status))


def wait_for_subscriber(session: zenoh.Session, key: str, timeout: float) -> bool:
    """Wait until something subscribes to ``key``; False after ``timeout`` seconds.

    A put made before the subscription is known goes nowhere, so short-lived publishers
    wait first.

    Raises:
        TransportError: the key is invalid.
    """
    with translate_zerror(f"publisher on {key!r}"):
        pub = session.declare_publisher(key)
    try:
        deadline = time.monotonic() + timeout
        while not matching(pub):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True
    finally:
        with contextlib.suppress(zenoh.ZError):
            pub.undeclare()


def declare_fifo_subscriber(
    session: zenoh.Session, key_expr: str, capacity: int = 65536
) -> zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]:
    """Declare a subscriber whose samples queue in a FIFO channel.

    A full FIFO makes Zenoh push back on publishers (with BLOCK congestion control) rather
    than drop, which is what a recorder wants.

    Raises:
        TransportError: the key expression is invalid or the declaration failed.
    """
    with translate_zerror(f"subscription to {key_expr!r}"):
        return session.declare_subscriber(key_expr, zenoh.handlers.FifoChannel(capacity))


def heartbeat_keys(key_expr: str) -> str:
    """The key expression of the sample-miss heartbeats of publishers on ``key_expr``.

    zenoh-ext's AdvancedPublisher announces its last sequence number on
    ``<key>/@adv/pub/<zid>/<eid>/_``; ``@adv`` is a verbatim chunk, so no subscription to the
    variables themselves receives them.
    """
    return f"{key_expr}/@adv/pub/**"


class _Source:
    """One numbered publisher, as the miss counter follows it."""

    __slots__ = ("beat", "expected", "key", "zid", "zid_text")

    def __init__(self, zid: Any, key: str) -> None:
        self.zid = zid
        self.zid_text = str(zid)
        #: the key of its first sample (a zenoh-ext publisher has one key)
        self.key = key
        #: the next sequence number expected; -1 before its first sample
        self.expected = -1
        #: a heartbeat not yet trusted: (when read, the last number sent)
        self.beat: tuple[float, int] | None = None


class MissCounter:
    """Counts the samples that publishers with sample-miss detection lost on their way here.

    zenoh-ext's AdvancedPublisher with ``sample_miss_detection`` (``MoosPublisher(drop=True)``
    is one) numbers each publisher's samples 0, 1, 2, … in the sample's source info. A gap in
    one publisher's numbers is samples that never arrived: DROP congestion control dropped them
    on a congested link. Losses at the end of a burst show no gap until the publisher's next
    sample; its periodic heartbeat (the last number it sent) reveals them sooner.

    Plain samples (no source info) are not looked at, and no sample is ever held back or
    filtered: this only counts. Counting starts at the first sample of each publisher that
    arrives. Everything runs in the thread that drains the subscribers (no callback, no lock).

    Args:
        clock: a monotonic clock, seconds.
        settle_delay: a heartbeat is trusted only this long after it was read, and only once
            the subscribers were seen empty after that: a sample numbered before the heartbeat
            may still be queued behind it.
    """

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, settle_delay: float = 0.5
    ) -> None:
        self._clock = clock
        self._settle_delay = settle_delay
        #: entity id → the publisher last seen with it (the fast path: a zid comparison)
        self._latest: dict[int, _Source] = {}
        #: (zid, entity id) → publisher; EntityGlobalId itself hashes by identity
        self._sources: dict[tuple[Any, int], _Source] = {}
        #: (zid text, entity id) → publisher, for heartbeats, whose key spells the id
        self._by_text: dict[tuple[str, int], _Source] = {}
        self._waiting: list[_Source] = []
        self._found: dict[tuple[str, str], int] = {}

    def seen(self, info: Any, sample: zenoh.Sample) -> None:
        """Account for a received sample whose ``source_info`` is ``info`` (not None)."""
        source_id = info.source_id
        zid = source_id.zid
        eid = source_id.eid
        sn = info.source_sn
        source = self._latest.get(eid)
        if source is None or source.zid != zid:
            source = self._source(zid, eid, sample)
        expected = source.expected
        if sn != expected and expected >= 0:
            if sn < expected:
                return  # late or repeated, not a loss
            self._add(source, sn - expected)
        source.expected = sn + 1

    def _source(self, zid: Any, eid: int, sample: zenoh.Sample) -> _Source:
        source = self._sources.get((zid, eid))
        if source is None:
            if len(self._sources) >= 65536:
                # Bounded like the other per-key caches; counting restarts for each publisher.
                self._sources.clear()
                self._latest.clear()
                self._by_text.clear()
                self._waiting.clear()
            source = _Source(zid, str(sample.key_expr))
            self._sources[(zid, eid)] = source
            self._by_text[(source.zid_text, eid)] = source
        self._latest[eid] = source
        return source

    def _add(self, source: _Source, count: int) -> None:
        name = (source.key, source.zid_text)
        self._found[name] = self._found.get(name, 0) + count

    def heartbeat(self, sample: zenoh.Sample) -> None:
        """Note a heartbeat (a sample of :func:`heartbeat_keys`); malformed ones are ignored."""
        key = str(sample.key_expr)
        _, sep, rest = key.rpartition("/@adv/pub/")
        parts = rest.split("/")
        payload = sample.payload.to_bytes()
        if not sep or len(parts) < 2 or len(payload) != 4 or not parts[1].isdigit():
            return
        source = self._by_text.get((parts[0], int(parts[1])))
        if source is None or source.beat is not None:
            return  # not a publisher seen here yet, or an older heartbeat still waits
        source.beat = (self._clock(), int.from_bytes(payload, "little"))
        self._waiting.append(source)

    def settle(self, drained_at: float, min_age: float | None = None) -> None:
        """Count the losses that heartbeats read before ``drained_at`` reveal.

        Args:
            drained_at: when (on the counter's clock) every subscriber was last seen empty.
            min_age: trust heartbeats read at least this long ago (``settle_delay`` when None;
                0 at shutdown).
        """
        if not self._waiting:
            return
        age = self._settle_delay if min_age is None else min_age
        now = self._clock()
        waiting: list[_Source] = []
        for source in self._waiting:
            assert source.beat is not None
            read_at, last = source.beat
            if read_at > drained_at or now - read_at < age:
                waiting.append(source)
                continue
            source.beat = None
            if source.expected >= 0 and last >= source.expected:
                self._add(source, last - source.expected + 1)
                source.expected = last + 1
        self._waiting = waiting

    def due_in(self) -> float:
        """Return how long until the oldest waiting heartbeat may be trusted (inf: none waits).

        The drain thread reads heartbeats at its ticks; one read while it then sleeps is
        trusted ``settle_delay`` later, not at whatever tick comes next.
        """
        if not self._waiting:
            return math.inf
        beats = [source.beat[0] for source in self._waiting if source.beat is not None]
        return max(0.0, min(beats, default=math.inf) + self._settle_delay - self._clock())

    def take(self) -> list[tuple[str, str, int]]:
        """Return and forget the losses found so far: ``(key, publisher zid, count)``."""
        if not self._found:
            return []
        found = [(key, zid, count) for (key, zid), count in self._found.items()]
        self._found.clear()
        return found
